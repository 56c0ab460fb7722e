"""What a verb's result means for ``hpcosim``'s exit status.

0: done, and the result holds; 1: done, and the result is negative (one line on stderr,
``hpcosim: check failed: REASON``; what the verb wrote stays written); 2: bad input or usage
(``hpcosim: error: ...``, nothing written); 3: an internal error (a bug); 128 + N: ended
by signal N.  :data:`NEGATIVE_WHEN` says, per verb, when a result is negative; the README's
verb table and docs/cli.md carry the same words (tests check both).  The decisions are
plain functions of a verb's result (tested on their own and end to end).
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import typer

OK, NEGATIVE, BAD_INPUT, INTERNAL = 0, 1, 2, 3

#: ``hpcosim`` verb -> when it exits 1 ("-": never; its failures are bad input, exit 2)
NEGATIVE_WHEN: dict[tuple[str, ...], str] = {
    ("model", "check"): "a physics check fails",
    ("mocap", "synth"): "-",
    ("mocap", "inspect"): "-",
    ("mocap", "process"): "- (a take that fails a plausibility check is bad input)",
    ("gait", "fit"): "multi-contact: not the person's gait or `clfqp` does not walk it; "
                    "paper: the gait does not walk (falls, or its return map does not "
                    "contract)",
    ("gait", "export"): "-",
    ("gait", "library"): "a speed's gait does not walk with the held oracle",
    ("tube", "fit"): "leave-one-out coverage 0 or below `--min-coverage` (default: the "
                     "a posteriori guarantee 1 - eps)",
    ("tube", "refit"): "as `tube fit`, for the refitted tube or bound",
    ("experiments",): "a paper claim not reproduced (`paper_literal`, a documented negative "
                      "result, excepted); a multi-contact gait: `clfqp` does not walk it",
    ("demo",): "a stage's result negative; `--domains paper`: as `experiments` (`--quick`: "
               "claims not judged)",
    ("fmu", "build"): "fmpy's validation finds a problem",
    ("run",): "the walker falls or the run faults",
    ("controller", "serve"): "-",
    ("replay",): "a torque differs by more than `--tolerance`",
    ("animate",): "-",
    ("recording", "recover"): "-",
    ("recording", "export"): "-",
    ("sweep", "run"): "runs missing (interrupted, infrastructure errors); falls are results",
    ("sweep", "report"): "as `sweep run`, on the stored results",
    ("sweep", "replay"): "a column differs from the stored run, or the run is not stored",
}

#: claims the project documents as not reproduced (docs/experiments.md): the paper's literal
#: formulation falls on this loop; its "NOT reproduced" is the expected result
EXPECTED_NOT_REPRODUCED = frozenset({"paper_literal"})


@dataclass(frozen=True)
class Verdict:
    """A verb's result: holds (``reason`` None) or negative, with a one-line reason."""

    reason: str | None = None

    @property
    def holds(self) -> bool:
        return self.reason is None


HOLDS = Verdict()


def conclude(verdict: Verdict) -> None:
    """Exit 1 with ``hpcosim: check failed: REASON`` on stderr if ``verdict`` is negative."""
    if verdict.reason is not None:
        print(f"hpcosim: check failed: {' '.join(verdict.reason.split())}", file=sys.stderr)
        raise typer.Exit(NEGATIVE)


def model_check_verdict(rows: Sequence[Any]) -> Verdict:
    """``model check``: every row (``name``, ``ok``) holds."""
    bad = [r.name for r in rows if not r.ok]
    if bad:
        return Verdict(f"{len(bad)} of {len(rows)} model checks failed: " + "; ".join(bad))
    return HOLDS


def cosim_verdict(res: Any, steps: int) -> Verdict:
    """``run``: a fault or a fall is negative; a run the time limit ends without either
    holds (``steps`` requested)."""
    if res.faulted:
        return Verdict(f"the run faulted at t = {res.sim_time:.3f} s: {res.fault_reason}")
    if res.fell:
        return Verdict(f"the walker fell at t = {res.sim_time:.3f} s ({res.fall_reason}, "
                       f"code {res.fall_code}) after {res.steps} of {steps} steps")
    return HOLDS


def gait_verdict(verification: Mapping[str, Any]) -> Verdict:
    """``gait fit``: a verified gait that does not walk (written by ``--allow-unstable``),
    with the failed checks in the words of the refusal without it."""
    if not verification or verification.get("walks", True):
        return HOLDS
    from characterization.gait.fit import walking_failures

    return Verdict(f"the gait does not walk: {'; '.join(walking_failures(verification))}; "
                   "written by --allow-unstable, marked walks: false")


def coverage_verdict(what: str, credibility: Mapping[str, Any],
                     min_coverage: float | None = None) -> Verdict:
    """A tube's (or model-error bound's) leave-one-out coverage against its target:
    ``min_coverage``, default the a posteriori guarantee 1 - eps at the fit's confidence
    (the estimate below the certified lower bound contradicts it).  Coverage 0 is always
    negative; a bound fitted on too few steps for leave-one-out is not judged."""
    loo = credibility.get("leave_one_out") or {}
    cov = loo.get("coverage", loo.get("step_coverage"))
    if cov is None:
        return HOLDS
    post = credibility.get("a_posteriori") or {}
    eps = post.get("epsilon_tube", post.get("epsilon"))
    if cov <= 0.0:
        return Verdict(f"{what}: leave-one-out coverage 0 (no step lies inside the fit "
                       "without it); written all the same")
    if min_coverage is not None:
        target, named = min_coverage, "--min-coverage"
    elif eps is not None:
        target, named = 1.0 - float(eps), "the a posteriori guarantee 1 - eps ="
    else:
        return HOLDS
    if cov < target:
        return Verdict(f"{what}: leave-one-out coverage {cov:.2f} below {named} "
                       f"{target:.2f}; written all the same")
    return HOLDS


def uncounted_claims(metrics: Mapping[str, Any], *, judged: bool = True,
                     expected: Iterable[str] = EXPECTED_NOT_REPRODUCED) -> dict[str, str]:
    """Claims of ``metrics`` that are not reproduced and do not count against the result,
    with why: those of ``expected`` (documented negatives: "expected"), ``nominal_stable``
    when its evidence was skipped (``--no-eigen``: the nominal run completed, no eigenvalues),
    and every one when ``judged`` is False (``demo --quick``)."""
    out = {}
    nominal = metrics.get("nominal") or {}
    skipped = bool((nominal.get("run") or {}).get("success")) and not (
        nominal.get("stability") or {}).get("computed")
    for c in metrics.get("claims", []):
        if c["reproduced"]:
            continue
        if not judged:
            out[c["id"]] = "not judged: --quick"
        elif c["id"] in set(expected):
            out[c["id"]] = "expected"
        elif c["id"] == "nominal_stable" and skipped:
            out[c["id"]] = "not judged: no eigenvalues"
    return out


def claims_verdict(metrics: Mapping[str, Any], *, judged: bool = True,
                   expected: Iterable[str] = EXPECTED_NOT_REPRODUCED) -> Verdict:
    """``experiments`` / ``demo``: every claim of ``metrics`` reproduced but those
    :func:`uncounted_claims` names."""
    skip = uncounted_claims(metrics, judged=judged, expected=expected)
    bad = [c["id"] for c in metrics.get("claims", [])
           if not c["reproduced"] and c["id"] not in skip]
    if bad:
        return Verdict(f"{len(bad)} claim{'s' if len(bad) > 1 else ''} NOT reproduced: "
                       + ", ".join(bad) + " (report.md says why)")
    return HOLDS


def replay_verdict(max_diff: float, tolerance: float) -> Verdict:
    """``replay``: the largest torque difference (N m, motor side) within ``tolerance``."""
    if max_diff > tolerance:
        return Verdict(f"largest torque difference {max_diff:.3g} N m (motor) is above "
                       f"--tolerance {tolerance:g} N m")
    return HOLDS


def sweep_verdict(expected: int, kept: int) -> Verdict:
    """``sweep run`` / ``sweep report``: ``kept`` of ``expected`` runs have a result to keep
    (not an infrastructure error: those are retried by a resume)."""
    if kept < expected:
        return Verdict(f"{expected - kept} of {expected} runs have no result (interrupted or "
                       "infrastructure errors); run the sweep again to resume")
    return HOLDS


def combine(*verdicts: Verdict) -> Verdict:
    """One verdict: negative if any is, the reasons joined."""
    reasons = [v.reason for v in verdicts if v.reason is not None]
    return Verdict("; ".join(reasons)) if reasons else HOLDS
