"""Gait design (paper Sec. IV-A): Bezier regression, PHZD gait optimization, verification."""
