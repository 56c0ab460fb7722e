"""What a long run keeps in memory does not grow with its length (issue 39): the loop's log
without samples, the timing statistics (a histogram whose percentiles stay within 0.1 % of
numpy's over every value), and the MCAP writer's chunk indexes (kept as their summary
bytes).  The hour-long figure itself: ``benchmarks/bench_memory.py``."""

from __future__ import annotations

import io
import pickle
import tracemalloc

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from bus_schemas.recording.chunk_append import PackedChunkIndexes, pack_chunk_indexes
from hp_model.closed_loop import ClosedLoopMode
from orchestrator.cosim.result import ReplyTimes, reply_early_share, tick_breakdown
from orchestrator.loop import OracleLink, SimulatorPlant, run_loop
from prosthesis_controller.timing import Durations, Histogram, Tally
from tests.fmu_support import simulator, start_state


@pytest.mark.parametrize("draw", [
    lambda g, n: g.lognormal(12.3, 0.4, n),  # round trips of ~220 us, a tail to ms
    lambda g, n: g.integers(0, 3000, n),  # small values: one bin each below 1024
    lambda g, n: 2e5 + g.exponential(3e5, n),
])
def test_histogram_percentiles_within_a_tenth_of_a_percent_of_numpy(draw):
    g = np.random.default_rng(7)
    v = [int(x) for x in draw(g, 50_001)]
    h = Histogram(v)
    assert (h.count, h.total, h.largest, h.smallest) == (len(v), sum(v), max(v), min(v))
    assert h.mean == pytest.approx(np.mean(v), rel=1e-12)
    for q in (0, 0.5, 10, 50, 90, 99, 99.9, 100):
        exact = float(np.percentile(v, q))
        assert h.percentile(q) == pytest.approx(exact, rel=1e-3, abs=0.5), q
    assert h.percentile(0) == min(v) and h.percentile(100) == max(v)


def test_histogram_bins_are_bounded_by_the_values_range_not_their_count():
    """512 bins per octave at most: values spread over a decade (100 us .. 1 ms in ns) fill
    at most ~1700 bins, and four times as many values of the same spread no more."""
    g = np.random.default_rng(1)
    a, b = Histogram(), Histogram()
    for x in g.uniform(1e5, 1e6, 20_000):
        a.add(int(x))
    for x in g.uniform(1e5, 1e6, 80_000):
        b.add(int(x))
    assert len(b.bins) <= 512 * (np.log2(10) + 1)  # the decade's octaves, both ends partial
    assert len(b.bins) - len(a.bins) <= 0.1 * len(a.bins)  # nearly all filled already


def test_durations_and_reply_times_summaries():
    d = Durations()
    assert d.summary() == {"n": 0}
    for ns in (1000, 2000, 3000, 4000):
        d.add(ns)
    s = d.summary()
    assert s["n"] == 4 and s["mean_us"] == 2.5
    assert s["median_us"] == pytest.approx(2.5, rel=1e-3)  # 2000 and 3000 ns: bins of 2 ns
    assert s["p99_us"] == pytest.approx(np.percentile([1, 2, 3, 4], 99), rel=1e-3)
    t = ReplyTimes()
    assert t.latency_us() == {} and t.early_share() == 0.0
    waits = [5_000, 25_000, 19_999, 20_000]
    for rt, w in zip((200_000, 300_000, 400_000, 500_000), waits, strict=True):
        t.replied(rt, w)
    lat = t.latency_us()
    assert lat == {"median": pytest.approx(350.0, rel=1e-3),
                   "p99": pytest.approx(497.0, rel=1e-3), "max": 500.0, "n": 4}
    assert t.early_share() == reply_early_share(waits) == 0.5
    # the tick breakdown from tallies is the one from the lists
    lists = ([1000, 3000], [100, 300], [600, 2000], [50, 60], [400, 1500])
    assert tick_breakdown(*(Tally(x) for x in lists)) == tick_breakdown(*lists)


def test_loop_log_without_samples_keeps_the_same_state_for_n_and_4n_periods(
        model, template_gait):
    """``run_loop(samples=False, timed=True)`` (the co-simulation's): the log of a run 4x as
    long is no larger (it kept per-period lists before: ~140 bytes a period)."""
    def log_of(periods):
        q0, qd0 = start_state(template_gait)
        plant = SimulatorPlant(simulator(model, template_gait), q0, qd0,
                               mode=ClosedLoopMode.FULL)
        log = run_loop(plant, OracleLink(), steps=10**6, periods=periods, timed=True,
                       samples=False)
        assert log.periods == periods and log.fall is None and log.tick_ns.count == periods
        return log

    short, long = log_of(100), log_of(400)
    assert short.t == long.t == []
    assert abs(len(pickle.dumps(long)) - len(pickle.dumps(short))) <= 16


class _Sink:
    """An output stream that keeps nothing (its position only)."""

    def __init__(self) -> None:
        self.pos = 0

    def write(self, b: bytes) -> int:
        self.pos += len(b)
        return len(b)

    def tell(self) -> int:
        return self.pos


def _write(out: io.BytesIO | _Sink, spool: int | None, messages: int = 20_000) -> int:
    """``messages`` messages on 13 channels in 2 kB chunks to ``out``, the chunk indexes
    packed in a spool of ``spool`` bytes (None: the writer's own list); the memory [bytes]
    the writer held (traced) before it finished."""
    w = Writer(out, chunk_size=2000, compression=CompressionType.NONE)  # type: ignore[arg-type]
    w.start(profile="", library="test")
    if spool is not None:
        assert pack_chunk_indexes(w)
        w._Writer__chunk_indices = PackedChunkIndexes(spool)  # type: ignore[attr-defined]
    sid = w.register_schema(name="s", encoding="jsonschema", data=b"{}")
    cids = [w.register_channel(topic=f"/t{i}", message_encoding="json", schema_id=sid)
            for i in range(13)]
    tracemalloc.start()
    for k in range(messages):
        w.add_message(channel_id=cids[k % 13], log_time=k, data=b'{"a":123}', publish_time=k)
    held = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    if spool is not None:  # past its spool: on disk
        assert w._Writer__chunk_indices._file._rolled == (spool < 50_000)  # type: ignore
    w.finish()
    return held


def test_packed_chunk_indexes_write_the_same_bytes_in_bounded_memory():
    """The summary's bytes are the writer's own; kept in memory (a spool of 1 MiB) about
    200 bytes a chunk against ~1.3 KiB, and none once spilled to disk."""
    plain, packed, spilled = io.BytesIO(), io.BytesIO(), io.BytesIO()
    _write(plain, None)
    _write(packed, 1 << 20)
    _write(spilled, 4096)
    assert packed.getvalue() == plain.getvalue() == spilled.getvalue()
    chunks = len(make_reader(io.BytesIO(packed.getvalue())).get_summary().chunk_indexes)
    assert chunks > 300
    # what the writer keeps per chunk (its open chunk aside: < 2 kB in all)
    held_plain, held_packed, held_spilled = (_write(_Sink(), s) for s in (None, 1 << 20, 4096))
    assert held_spilled / chunks <= 30 < 100 <= held_packed / chunks <= 300 < 900 <= \
        held_plain / chunks
    # only an empty list is replaced (a writer that already finalized a chunk keeps its own)
    w = Writer(io.BytesIO())
    w._Writer__chunk_indices.append(object())  # type: ignore[attr-defined]
    assert not pack_chunk_indexes(w)
    p = PackedChunkIndexes()
    assert len(p) == 0 and list(p) == []
