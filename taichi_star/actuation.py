"""Actuation: the curvature an SMA actuator takes over one cycle (paper Eq. 5).

A fired actuator's arc follows K̄(τ), τ the time since it fired: a logistic fall while the SMA
wire heats (τ < t0), then a logistic recovery while it cools. The fit does not close on itself
(K̄ just before the next cycle is not K̄(0)); `closure="ramp"` spreads the difference linearly
over the period so that a periodic gait has a continuous natural curvature.
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass
from typing import Tuple

import numpy as np

PROFILE_CLOSURES = ("jump", "ramp")


@dataclass(frozen=True)
class CurvatureProfile:
    """Logistic fit of one actuator's natural curvature over a cycle (paper Eq. 5).

    K̄(τ) = c1/(1 + exp(−c2 (τ − c3))) + c4, with the heating constants for τ < t0 and the
    cooling constants for τ ≥ t0; τ in s, K̄ in 1/m. The defaults are the paper's fit.
    """

    heating: Tuple[float, float, float, float] = (-89.827, 62.724, 0.061, 104.040)
    """(c1a 1/m, c2a 1/s, c3a s, c4a 1/m) while the wire heats."""
    cooling: Tuple[float, float, float, float] = (94.777, 2.507, 1.019, 4.445)
    """(c1d 1/m, c2d 1/s, c3d s, c4d 1/m) while it cools."""
    switch_time: float = 0.163
    """t0, s: the end of the heating phase, where the curvature is smallest; > 0."""

    def __post_init__(self):
        for name in ("heating", "cooling"):
            values = tuple(float(v) for v in getattr(self, name))
            if len(values) != 4 or not all(math.isfinite(v) for v in values):
                raise ValueError(f"CurvatureProfile.{name} must be 4 finite numbers, got "
                                 f"{getattr(self, name)!r}")
            object.__setattr__(self, name, values)
        if not (isinstance(self.switch_time, (int, float)) and math.isfinite(self.switch_time)
                and self.switch_time > 0):
            raise ValueError(f"CurvatureProfile.switch_time must be a finite number > 0 s, got "
                             f"{self.switch_time!r}")
        if not self.rest_curvature > 0:
            raise ValueError(f"CurvatureProfile: K̄(0) must be > 0 1/m (the rest arc), got "
                             f"{self.rest_curvature!r}")

    def to_text(self) -> str:
        """The profile as one line of text, its repr (every constant to the last bit), which
        `from_text` reads back; how result tables store it."""
        return repr(self)

    @classmethod
    def from_text(cls, text: str) -> "CurvatureProfile":
        """The profile written by `to_text` ("CurvatureProfile(heating=(...), cooling=(...),
        switch_time=...)"); ValueError naming actuator_profile for any other text."""
        try:
            call = ast.parse(str(text).strip(), mode="eval").body
            if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Name)
                    and call.func.id == cls.__name__ and not call.args):
                raise ValueError
            values = {keyword.arg: ast.literal_eval(keyword.value) for keyword in call.keywords}
            return cls(**values)
        except (SyntaxError, ValueError, TypeError):
            raise ValueError(f"actuator_profile: {str(text)[:80]!r} is not a profile's text "
                             f"(CurvatureProfile(heating=(4 numbers), cooling=(4 numbers), "
                             f"switch_time=number))") from None

    def as_array(self) -> np.ndarray:
        """The nine constants (c1a..c4a, c1d..c4d, t0) in the order the kernels read them."""
        return np.array([*self.heating, *self.cooling, self.switch_time], dtype=np.float64)

    def curvature(self, tau):
        """K̄(τ) in 1/m for τ (s) since firing; scalar or array (Eq. 5 as fitted, no closure)."""
        tau = np.asarray(tau, dtype=np.float64)
        c1a, c2a, c3a, c4a = self.heating
        c1d, c2d, c3d, c4d = self.cooling
        heating = c1a / (1.0 + np.exp(-c2a * (tau - c3a))) + c4a
        cooling = c1d / (1.0 + np.exp(-c2d * (tau - c3d))) + c4d
        out = np.where(tau < self.switch_time, heating, cooling)
        return float(out) if out.ndim == 0 else out

    def closure_gap(self, period: float) -> float:
        """K̄(0) − K̄(T), 1/m: the step of the natural curvature where a new cycle starts."""
        return self.rest_curvature - self.curvature(period)

    def cycle_curvature(self, tau, period: float, closure: str = "jump"):
        """K̄ over a cycle of `period` s with the given closure: "jump" = Eq. 5 as fitted,
        "ramp" = K̄(τ) + (K̄(0) − K̄(T))·τ/T (continuous from one cycle to the next)."""
        if closure not in PROFILE_CLOSURES:
            raise ValueError(f"closure must be one of {list(PROFILE_CLOSURES)}, got {closure!r}")
        value = self.curvature(tau)
        if closure == "ramp":
            value = value + self.closure_gap(period) * np.asarray(tau, dtype=np.float64) / period
        return value

    @property
    def rest_curvature(self) -> float:
        """K̄(0), 1/m: the curvature of an actuator at rest (the arcs of the rest shape)."""
        return self.curvature(0.0)
