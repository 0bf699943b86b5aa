"""Actuation: the SMA curvature profile (paper Eq. 5), gaits, and the octagon's symmetries.

A gait is a set of actuators fired together every cycle, written "A1+A3+A5" (actuators
A1..A8, no repeats) or "none" for a robot that is never actuated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple

import numpy as np

N_ACTUATORS = 8
NO_GAIT = "none"


@dataclass(frozen=True)
class CurvatureProfile:
    """Logistic fit of one actuator's natural curvature over a cycle (paper Eq. 5).

    K(tau) = c1/(1 + exp(-c2 (tau - c3))) + c4, with the actuation constants for tau < t0 and
    the de-actuation constants for tau >= t0. tau in s, K in 1/m.
    """

    actuation: Tuple[float, float, float, float] = (-89.827, 62.724, 0.061, 104.040)
    deactuation: Tuple[float, float, float, float] = (94.777, 2.507, 1.019, 4.445)
    switch_time: float = 0.163
    """t0, s: the fitted end of the heating phase, where the curvature is smallest."""

    def as_array(self) -> np.ndarray:
        """The nine constants (c1a..c4a, c1d..c4d, t0) in the order the kernels read them."""
        return np.array([*self.actuation, *self.deactuation, self.switch_time], dtype=np.float64)

    def curvature(self, tau):
        """K(tau) in 1/m for tau (s) within a cycle; scalar or array."""
        tau = np.asarray(tau, dtype=np.float64)
        c1a, c2a, c3a, c4a = self.actuation
        c1d, c2d, c3d, c4d = self.deactuation
        heating = c1a / (1.0 + np.exp(-c2a * (tau - c3a))) + c4a
        cooling = c1d / (1.0 + np.exp(-c2d * (tau - c3d))) + c4d
        out = np.where(tau < self.switch_time, heating, cooling)
        return float(out) if out.ndim == 0 else out

    @property
    def rest_curvature(self) -> float:
        """K(0), 1/m: the curvature of an actuator at rest (the arcs of the rest shape)."""
        return self.curvature(0.0)


PAPER_PROFILE = CurvatureProfile()


def parse_gait(gait: str) -> Tuple[int, ...]:
    """Actuator numbers (1..8, sorted) of a gait string such as "A1+A3+A5"; () for "none".

    Raises ValueError naming the gait and the allowed form for anything else.
    """
    allowed = 'allowed: "none" or actuators "A1".."A8" joined by "+", each at most once'
    if not isinstance(gait, str):
        raise ValueError(f"gait must be a string ({allowed}), got {gait!r}")
    if gait.strip().lower() == NO_GAIT:
        return ()
    numbers = []
    for token in gait.split("+"):
        token = token.strip()
        if len(token) != 2 or token[0] not in "Aa" or token[1] not in "12345678":
            raise ValueError(f"gait {gait!r}: unknown actuator {token!r} ({allowed})")
        numbers.append(int(token[1]))
    if len(set(numbers)) != len(numbers):
        raise ValueError(f"gait {gait!r}: an actuator is repeated ({allowed})")
    return tuple(sorted(numbers))


def gait_name(actuators) -> str:
    """Canonical name of a set of actuator numbers: (3, 1) -> "A1+A3"; () -> "none"."""
    actuators = sorted(int(a) for a in actuators)
    return "+".join(f"A{a}" for a in actuators) if actuators else NO_GAIT


def gait_mask(gait: str) -> np.ndarray:
    """int32 array (8,): 1 where actuator A(m+1) fires in this gait."""
    mask = np.zeros(N_ACTUATORS, dtype=np.int32)
    for number in parse_gait(gait):
        mask[number - 1] = 1
    return mask


def actuator_direction(number: int) -> np.ndarray:
    """Unit bisector u_m of actuator A_m (design §3): angle (m - 1)·45°."""
    angle = math.radians(45.0 * (number - 1))
    return np.array([math.cos(angle), math.sin(angle)])


def forward_direction(gait: str):
    """Normalised sum of the gait's actuator bisectors, or None where it is undefined (zero sum)."""
    actuators = parse_gait(gait)
    if not actuators:
        return None
    total = sum(actuator_direction(a) for a in actuators)
    norm = float(np.hypot(*total))
    if norm < 1e-9:
        return None
    return total / norm


def transform_gait(gait: str, rotation: int, reflect: bool) -> str:
    """Image of a gait under an octagon symmetry: optional reflection across the A1 axis
    (A_m -> A_{2-m}, indices mod 8), then rotation by `rotation`·45° (A_m -> A_{m+rotation})."""
    images = []
    for number in parse_gait(gait):
        index = number - 1
        if reflect:
            index = -index
        images.append((index + rotation) % N_ACTUATORS + 1)
    return gait_name(images)


def symmetry_classes():
    """The 255 non-empty gaits grouped under the octagon's 16 symmetries.

    Returns a list of (representative, members) with the representative the smallest member in
    (size, bitmask) order and members sorted; there are 29 classes.
    """
    def key(name):
        bits = parse_gait(name)
        return (len(bits), sum(1 << (b - 1) for b in bits))

    seen = set()
    classes = []
    for bits in range(1, 1 << N_ACTUATORS):
        name = gait_name(m + 1 for m in range(N_ACTUATORS) if bits >> m & 1)
        if name in seen:
            continue
        members = {transform_gait(name, r, f) for r in range(N_ACTUATORS) for f in (False, True)}
        seen |= members
        ordered = sorted(members, key=key)
        classes.append((ordered[0], ordered))
    return classes
