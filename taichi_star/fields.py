"""One SNode tree per engine: Taichi gives every field created after the first kernel launch a
tree of its own, and a program holds a limited number of trees (a process that builds many
engines, each with dozens of fields, would run out and crash). A FieldArena places all of an
engine's fields in one tree, and fills its index tables once the tree exists.

Fields with a leading batch axis (`batch_field`) are laid out instance-major on the CPU (one
instance's values contiguous: one thread walks its own instance through the cache) and, with
`instance_minor`, instance-minor on a GPU (the same element of consecutive instances adjacent:
the threads of a warp, one instance each, read one contiguous run of memory).
The index `[b, ...]` is the same in both layouts; only the addresses differ."""

from typing import Optional

import numpy as np
import taichi as ti
from taichi.lang.util import cook_dtype, to_numpy_type


class FieldArena:
    """Collects fields (`field`, `index`) and creates them together in `finalize`."""

    def __init__(self, instance_minor: bool = False):
        self.instance_minor = instance_minor
        self.nbytes = 0
        """Bytes of the fields collected so far."""
        self.builder = ti.FieldsBuilder()
        self.pending = []
        self.tree = None

    def field(self, dtype, shape=(), vector: Optional[int] = None, matrix: Optional[tuple] = None):
        """A scalar (or `vector`-long vector, or `matrix` = (rows, columns)) field of `shape`,
        stored row-major, usable once the arena is finalized."""
        field, shape = self.new(dtype, shape, vector, matrix)
        if shape:
            self.builder.dense(ti.axes(*range(len(shape))), shape).place(field)
        else:
            self.builder.place(field)
        return field

    def batch_field(self, dtype, shape, vector: Optional[int] = None,
                    matrix: Optional[tuple] = None):
        """Like `field`, for a `shape` = (capacity, ...) whose first axis is the instance: stored
        instance-minor when the arena is (see the module docstring)."""
        field, shape = self.new(dtype, shape, vector, matrix)
        if self.instance_minor and len(shape) > 1:
            self.builder.dense(ti.axes(*range(1, len(shape))), shape[1:]).dense(
                ti.axes(0), shape[0]).place(field)
        else:
            self.builder.dense(ti.axes(*range(len(shape))), shape).place(field)
        return field

    def new(self, dtype, shape, vector, matrix):
        """(unplaced field, shape as a tuple of ints); counts its bytes."""
        if vector is not None:
            field = ti.Vector.field(vector, dtype)
        elif matrix is not None:
            field = ti.Matrix.field(matrix[0], matrix[1], dtype)
        else:
            field = ti.field(dtype)
        shape = (shape,) if isinstance(shape, (int, np.integer)) else tuple(int(n) for n in shape)
        components = vector or (matrix[0] * matrix[1] if matrix else 1)
        self.nbytes += int(np.prod(shape, dtype=np.int64)) * components * np.dtype(to_numpy_type(cook_dtype(dtype))).itemsize
        return field, shape

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
