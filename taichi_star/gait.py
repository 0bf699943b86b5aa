"""Gaits: which of the eight actuators fire together, as a value parsed once.

A gait is written "A1+A3+A5" (actuators A1..A8, each at most once, any order, case-insensitive)
or "none" for a robot that is never actuated. `Gait.parse` turns any such text into a `Gait`
whose `name` is canonical (sorted: "A2+A1" -> "A1+A2"); everything else (the actuator mask, the
forward direction, the images under the octagon's symmetries) is read off that value.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import List, Optional, Tuple, Union

import numpy as np
from .checks import check_flag, is_whole

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["Gait", "all_gaits", "symmetry_classes", "N_ACTUATORS"]

N_ACTUATORS = 8
NO_GAIT = "none"
_ALLOWED = 'allowed: "none" or actuators "A1".."A8" joined by "+", each at most once'


def actuator_direction(number: int) -> np.ndarray:
    """Unit bisector u_m (2,) of actuator A_m: the angle (m − 1)·45° from +x."""
    angle = math.radians(45.0 * (number - 1))
    return np.array([math.cos(angle), math.sin(angle)])


@dataclass(frozen=True)
class Gait:
    """A set of actuators (numbers 1..8, sorted, no repeats) fired together."""

    actuators: Tuple[int, ...] = ()

    def __post_init__(self):
        # whole numbers only: int() would take 1.5 for A1, True for A1 and "12" for A1+A2
        given = self.actuators
        if isinstance(given, (str, bytes)) or not hasattr(given, "__iter__") or any(
                not is_whole(a) for a in given):
            raise ValueError(f"gait actuators must be numbers 1..{N_ACTUATORS}, got {given!r}")
        numbers = tuple(int(a) for a in given)
        if any(not 1 <= a <= N_ACTUATORS for a in numbers):
            raise ValueError(f"gait actuators must be numbers 1..{N_ACTUATORS}, got {self.actuators!r}")
        if len(set(numbers)) != len(numbers):
            raise ValueError(f"gait actuators must not repeat, got {self.actuators!r}")
        object.__setattr__(self, "actuators", tuple(sorted(numbers)))

    @classmethod
    def parse(cls, gait: Union[str, "Gait"]) -> "Gait":
        """The Gait of a text such as "A1+A3" or "none" (or a Gait, returned as is).

        Raises ValueError naming the text and the allowed form for anything else."""
        if isinstance(gait, Gait):
            return gait
        if not isinstance(gait, str):
            raise ValueError(f"gait must be a string ({_ALLOWED}), got {gait!r}")
        return cls._from_text(gait)

    @classmethod
    @functools.lru_cache(maxsize=1024)
    def _from_text(cls, gait: str) -> "Gait":
        # once per distinct text: a batch of 65,536 names a few gaits, and a Gait is immutable
        if gait.strip().lower() == NO_GAIT:
            return cls(())
        numbers = []
        for token in gait.split("+"):
            token = token.strip()
            if len(token) != 2 or token[0] not in "Aa" or token[1] not in "12345678":
                raise ValueError(f"gait {gait!r}: unknown actuator {token!r} ({_ALLOWED})")
            numbers.append(int(token[1]))
        if len(set(numbers)) != len(numbers):
            raise ValueError(f"gait {gait!r}: an actuator is repeated ({_ALLOWED})")
        return cls(tuple(numbers))

    @classmethod
    def from_mask(cls, mask) -> "Gait":
        """The Gait of a boolean/0-1 sequence of length 8 (entry m fires actuator A(m+1))."""
        mask = np.asarray(mask)
        if mask.shape != (N_ACTUATORS,):
            raise ValueError(f"an actuator mask must have shape ({N_ACTUATORS},), got {mask.shape}")
        # a NaN, a 2 or a text would be nonzero: fired
        if not (mask.dtype == bool or (mask.dtype.kind in "iu" and np.isin(mask, (0, 1)).all())):
            raise ValueError(f"an actuator mask must be boolean (or 0/1 integers), got "
                             f"{mask.tolist()!r}")
        return cls(tuple(int(m) + 1 for m in np.flatnonzero(mask)))

    @property
    def name(self) -> str:
        """Canonical text: actuators in increasing order joined by "+", or "none"."""
        return "+".join(f"A{a}" for a in self.actuators) if self.actuators else NO_GAIT

    def __str__(self) -> str:
        return self.name

    @property
    def mask(self) -> np.ndarray:
        """int32 (8,): 1 where actuator A(m+1) fires."""
        mask = np.zeros(N_ACTUATORS, dtype=np.int32)
        mask[[a - 1 for a in self.actuators]] = 1
        return mask

    @property
    def bits(self) -> int:
        """The mask as an integer, bit m for actuator A(m+1)."""
        return sum(1 << (a - 1) for a in self.actuators)

    @property
    def forward(self) -> Optional[np.ndarray]:
        """Unit (2,) sum of the actuators' bisectors, or None where it vanishes (e.g. A1+A5, "none")."""
        if not self.actuators:
            return None
        total = sum(actuator_direction(a) for a in self.actuators)
        norm = float(np.hypot(*total))
        return None if norm < 1e-9 else total / norm

    def transform(self, rotation: int, reflect: bool) -> "Gait":
        """Image under an octagon symmetry: optional reflection across the A1 axis
        (A_m -> A_{2−m}, indices mod 8), then rotation by `rotation`·45° (A_m -> A_{m+rotation}).
        ValueError naming rotation unless it is an integer (any: taken mod 8), or reflect
        unless it is True or False (a text "no" would reflect)."""
        if not is_whole(rotation):
            raise ValueError(f"rotation must be an integer number of 45° turns (taken mod "
                             f"{N_ACTUATORS}), got {rotation!r}")
        rotation, reflect = int(rotation), check_flag("reflect", reflect)
        images = []
        for number in self.actuators:
            index = -(number - 1) if reflect else number - 1
            images.append((index + rotation) % N_ACTUATORS + 1)
        return Gait(tuple(images))

    @property
    def symmetric_images(self) -> List["Gait"]:
        """The distinct images under the 16 symmetries, sorted by (size, bits)."""
        images = {self.transform(r, f) for r in range(N_ACTUATORS) for f in (False, True)}
        return sorted(images, key=lambda g: (len(g.actuators), g.bits))


def canonical_gait(gait: Union[str, Gait]) -> str:
    """Canonical name of a gait text: canonical_gait("a3+A1") == "A1+A3"."""
    return Gait.parse(gait).name


def all_gaits() -> List[str]:
    """The 255 non-empty gaits by their actuators' bits (A1, A2, A1+A2, A3, ...)."""
    return [Gait.from_mask([(bits >> m) & 1 for m in range(N_ACTUATORS)]).name
            for bits in range(1, 1 << N_ACTUATORS)]


def symmetry_classes() -> List[Tuple[str, List[str]]]:
    """The 255 non-empty gaits grouped under the octagon's 16 symmetries (29 classes).

    Returns (representative, members) pairs; the representative is the smallest member in
    (size, bits) order, members are sorted the same way."""
    seen = set()
    classes = []
    for name in all_gaits():
        gait = Gait.parse(name)
        if gait in seen:
            continue
        members = gait.symmetric_images
        seen.update(members)
        classes.append((members[0].name, [m.name for m in members]))
    return classes
