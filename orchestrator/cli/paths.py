"""Every path a verb is given is taken relative to the user's working folder.

The verbs' ``Path`` parameters are made absolute (``~`` expanded; symbolic links are *not*
resolved, so a verb writing through a link still sees it) before the verb runs, whatever it
then starts in another folder (the controller process runs in the checkout, sweep workers
where Dask starts them).  :func:`absolutize` wraps every command of the ``hpcosim`` app once,
so a verb added later is covered without a change here; verbs that take a path as text
(globs, ``RUN.mcap|SCENARIO``) make it absolute themselves with :func:`absolute`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import typer

F = TypeVar("F", bound=Callable[..., Any])

_MARK = "__hpcosim_absolute_paths__"


def absolute(p: str | Path) -> Path:
    """``p`` from the working folder, as an absolute path (``~`` expanded, links kept)."""
    return Path(p).expanduser().absolute()


def _absolute_value(v: Any) -> Any:
    if isinstance(v, Path):
        return absolute(v)
    if isinstance(v, list | tuple) and v and all(isinstance(x, Path) for x in v):
        return type(v)(absolute(x) for x in v)
    return v


def absolute_paths(fn: F) -> F:
    """``fn`` with every ``Path`` argument (and list of them) made absolute first."""
    if getattr(fn, _MARK, False):
        return fn

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        # the verb is looked up at call time (a test may stand in for it; typer reads the
        # signature through ``__wrapped__`` too)
        verb = wrapper.__wrapped__
        return verb(*(_absolute_value(a) for a in args),
                    **{k: _absolute_value(v) for k, v in kwargs.items()})

    setattr(wrapper, _MARK, True)
    return wrapper  # type: ignore[return-value]


def absolutize(app: typer.Typer) -> None:
    """Wrap the callback of every command of ``app`` and its sub-apps (idempotent)."""
    for info in app.registered_commands:
        if info.callback is not None:
            info.callback = absolute_paths(info.callback)
    for group in app.registered_groups:
        if group.typer_instance is not None:
            absolutize(group.typer_instance)


def is_absolutized(fn: Callable[..., Any]) -> bool:
    """Whether ``fn`` makes its path arguments absolute (:func:`absolute_paths`)."""
    return bool(getattr(fn, _MARK, False))
