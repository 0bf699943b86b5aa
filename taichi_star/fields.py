"""One SNode tree per engine: Taichi gives every field created after the first kernel launch a
tree of its own, and a program holds a limited number of trees (a process that builds many
engines, each with dozens of fields, would run out and crash). A FieldArena places all of an
engine's fields in one tree, and fills its index tables once the tree exists."""

from typing import Optional

import numpy as np
import taichi as ti


class FieldArena:
    """Collects fields (`field`, `index`) and creates them together in `finalize`."""

    def __init__(self):
        self.builder = ti.FieldsBuilder()
        self.pending = []
        self.tree = None

    def field(self, dtype, shape=(), vector: Optional[int] = None, matrix: Optional[tuple] = None):
        """A scalar (or `vector`-long vector, or `matrix` = (rows, columns)) field of `shape`,
        usable once the arena is finalized."""
        if vector is not None:
            field = ti.Vector.field(vector, dtype)
        elif matrix is not None:
            field = ti.Matrix.field(matrix[0], matrix[1], dtype)
        else:
            field = ti.field(dtype)
        shape = (shape,) if isinstance(shape, (int, np.integer)) else tuple(int(n) for n in shape)
        if shape:
            self.builder.dense(ti.axes(*range(len(shape))), shape).place(field)
        else:
            self.builder.place(field)
        return field

    def index(self, values) -> ti.Field:
        """An i32 field holding the (non-empty) integer table `values`, filled at finalize."""
        values = np.ascontiguousarray(values, dtype=np.int32)
        field = self.field(ti.i32, values.shape)
        self.pending.append((field, values))
        return field

    def finalize(self):
        """Create the tree and fill the index tables."""
        self.tree = self.builder.finalize()
        for field, values in self.pending:
            field.from_numpy(values)
        self.pending = []
