"""Which subject a verb uses: ``--subject FILE`` when given, else the one stored in the
artifact it reads (the steps of ``mocap process``, the gait of ``gait fit``), else the
shipped example subject (:func:`hp_model.config.load_subject` reads all three)."""

from __future__ import annotations

from pathlib import Path

from hp_model.config import ConfigError, SubjectConfig, load_subject, stored_subject


def subject_source(subject: Path | None, artifact: Path | None) -> str | None:
    """The subject for a verb reading ``artifact``: ``--subject``'s file, else the artifact
    when it stores a subject (its path: every consumer of a subject path reads it), else
    None (the shipped example).  A missing artifact is left to the verb's own reading; a
    stored subject that is not valid is a :class:`ConfigError` (one line)."""
    if subject is not None:
        return str(subject)
    if artifact is None or not artifact.is_file():
        return None
    return str(artifact) if stored_subject(artifact) is not None else None


def subject_note(subject: Path | None, artifact: Path) -> str:
    """One line: which subject is used, and whether ``--subject`` differs from the one the
    artifact stores."""
    found = _stored(artifact)
    if subject is not None:
        given = load_subject(subject)
        if found is not None and found.model_dump() != given.model_dump():
            return (f"subject: '{given.name}' from --subject {subject}, not the one stored in "
                    f"{artifact.name} ('{found.name}', {found.body_mass:g} kg)")
        return f"subject: '{given.name}' ({given.body_mass:g} kg) from --subject {subject}"
    if found is not None:
        return f"subject: '{found.name}' ({found.body_mass:g} kg) stored in {artifact.name}"
    return (f"subject: the shipped example ({artifact.name} stores none; remake it with "
            "hpcosim mocap process, or give --subject)")


def _stored(artifact: Path) -> SubjectConfig | None:
    try:
        found = stored_subject(artifact)
    except ConfigError:
        return None
    return None if found is None else found[0]
