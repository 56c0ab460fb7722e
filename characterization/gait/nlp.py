"""A nonlinear program under construction for CasADi's nlpsol: decision variables with their
initial guess and bounds, constraints with their bounds, in the order they are added.  The
gait optimizations (:mod:`characterization.gait.phzd`, :mod:`characterization.gait.multicontact`)
build theirs with it."""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike


class NLP:
    """The NLP under construction: the decision variables w (initial guess w0, bounds lbw,
    ubw) and the constraints g (bounds lbg, ubg), in the order they are added."""

    def __init__(self) -> None:
        self.w: list[ca.MX] = []
        self.w0: list[np.ndarray] = []
        self.lbw: list[np.ndarray] = []
        self.ubw: list[np.ndarray] = []
        self.g: list[ca.MX] = []
        self.lbg: list[np.ndarray] = []
        self.ubg: list[np.ndarray] = []
        self.blocks: dict[str, int] = {}  # a variable block's name -> its index in w

    def var(self, name: str, shape: tuple[int, int], init: ArrayLike, lb: ArrayLike = -np.inf,
            ub: ArrayLike = np.inf) -> ca.MX:
        """A new block of variables (column-major in w) with its initial guess and bounds."""
        v = ca.MX.sym(name, *shape)
        self.blocks[name] = len(self.w)
        self.w.append(ca.vec(v))
        init = np.asarray(init, dtype=float)
        if init.ndim == 1 and shape[1] == 1:
            init = init[:, None]
        self.w0.append(np.broadcast_to(init, shape).ravel(order="F"))
        self.lbw.append(np.broadcast_to(lb, shape).ravel(order="F"))
        self.ubw.append(np.broadcast_to(ub, shape).ravel(order="F"))
        return v

    def span(self, name: str) -> slice:
        """Where the block ``name`` lies in w (and in the bounds concatenated)."""
        k = self.blocks[name]
        start = sum(len(b) for b in self.lbw[:k])
        return slice(start, start + len(self.lbw[k]))

    def eq(self, expr: ca.MX) -> None:
        """expr = 0 (every element)."""
        self.g.append(ca.vec(expr))
        self.lbg.append(np.zeros(self.g[-1].shape[0]))
        self.ubg.append(np.zeros(self.g[-1].shape[0]))

    def geq(self, expr: ca.MX, lo: float = 0.0) -> None:
        """expr >= lo (every element)."""
        self.g.append(ca.vec(expr))
        self.lbg.append(np.full(self.g[-1].shape[0], lo))
        self.ubg.append(np.full(self.g[-1].shape[0], np.inf))

    def within(self, expr: ca.MX, lo: float, hi: float) -> None:
        """lo <= expr <= hi, expr a scalar."""
        self.g.append(expr)
        self.lbg.append(np.array([lo]))
        self.ubg.append(np.array([hi]))
