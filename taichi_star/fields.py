"""One SNode tree per engine: Taichi gives every field created after the first kernel launch a
tree of its own, and a program holds a limited number of trees (a process that builds many
engines, each with dozens of fields, would run out and crash). A FieldArena places all of an
engine's fields in one tree, and fills its index tables once the tree exists.

Fields with a leading batch axis (`batch_field`) are laid out instance-major on the CPU (one
instance's values contiguous: one thread walks its own instance through the cache) and, with
`instance_minor`, instance-minor on a GPU (the same element of consecutive instances adjacent:
the threads of a warp, one instance each, read one contiguous run of memory).
The index `[b, ...]` is the same in both layouts; only the addresses differ."""

import warnings
from typing import Dict, Optional, Sequence

import numpy as np
import taichi as ti
from taichi.lang.matrix import MatrixField
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

    def finalize(self, fill_tables: bool = True):
        """Create the tree and fill the index tables, or with `fill_tables` False leave them to
        the owner, who writes `tables()` with its own store (one kernel fewer to compile)."""
        self.tree = self.builder.finalize()
        if fill_tables and self.pending:
            tables = self.tables()
            FieldStore({key: field for key, (field, _) in tables.items()}).write(
                {key: values for key, (_, values) in tables.items()})

    def destroy(self):
        """Give the tree's memory back to the system; its fields (and the kernels that read
        them) are unusable after."""
        if self.tree is not None:
            self.tree.destroy()
            self.tree = None

    def tables(self) -> Dict[str, tuple]:
        """The index tables: name -> (field, values)."""
        return {f"table.{number}": entry for number, entry in enumerate(self.pending)}


def array_shape(field) -> tuple:
    """Shape of a field's values as one NumPy array (the component axes last)."""
    return tuple(field.shape) + _components(field)


def array_dtype(field) -> np.dtype:
    """NumPy dtype of a field's values."""
    return np.dtype(to_numpy_type(field.dtype))


def _components(field) -> tuple:
    """Per-element component shape of a field: () scalar, (n,) vector, (n, m) matrix."""
    if isinstance(field, MatrixField):
        return (field.n,) if field.ndim == 1 else (field.n, field.m)
    return ()


_FLOAT, _INT, _ZERO = 0, 1, 2
"""What a store does with a field: copy it through the float64 or the int64 array, or zero it."""


@ti.data_oriented
class FieldStore:
    """Copies NumPy arrays into a fixed set of fields in one kernel launch (and back).

    Taichi compiles `from_numpy`/`fill`/`to_numpy` once per field, and an engine has dozens of
    fields, all new for every engine built: those small compilations cost more than the
    engine's own kernels. A store packs every value into one float64 and one int64 array and
    scatters them with one kernel, compiled once per store, with one parallel loop per shape
    of the fields (each loop is a function LLVM compiles apart: an engine's load store of ~100
    fields in ~20 shapes compiled in 0.56 s where a loop per field took 1.83 s, cold, on a
    2-core Intel Xeon; docs/performance.md, "Compile time"). Values are cast to each field's type
    exactly as `from_numpy` would (float64 → float32 rounds to nearest; integers are exact), so a
    `write` of what `read` returned restores the fields bitwise.

    `zeroed`: names of fields that a `write` sets to zero on the device instead of copying
    (a store that resets a large batch to rest need not pack gigabytes of zeros on the host);
    such a store does not `read`."""

    def __init__(self, fields: Dict[str, ti.Field], zeroed: Sequence[str] = ()):
        unknown = set(zeroed) - set(fields)
        if unknown:
            raise ValueError(f"zeroed fields {sorted(unknown)} are not fields of the store")
        copied = {name: field for name, field in fields.items() if name not in zeroed}
        self.shapes = {name: array_shape(field) for name, field in copied.items()}
        self.dtypes = {name: array_dtype(field) for name, field in copied.items()}
        floating = {name: np.issubdtype(self.dtypes[name], np.floating) for name in copied}
        self.layout = {True: [], False: []}
        """Per kind (True: float): (name, offset into the flat array, size) in packing order."""
        totals = {True: 0, False: 0}
        for name in copied:
            size = int(np.prod(self.shapes[name], dtype=np.int64))
            self.layout[floating[name]].append((name, totals[floating[name]], size))
            totals[floating[name]] += size
        self.zeroed_fields = [fields[name] for name in zeroed]
        entries = [(copied[name], _FLOAT if kind else _INT, offset,
                    int(np.prod(_components(copied[name]), dtype=np.int64)))
                   for kind in (True, False) for name, offset, _ in self.layout[kind]]
        entries += [(field, _ZERO, 0, 0) for field in self.zeroed_fields]
        self.scalars = [entry for entry in entries if not entry[0].shape]
        """(field, kind, offset, components) of the 0-D fields."""
        by_shape: Dict[tuple, list] = {}
        for entry in entries:
            if entry[0].shape:
                by_shape.setdefault(tuple(entry[0].shape), []).append(entry)
        self.by_shape = list(by_shape.items())
        """(shape, [(field, kind, offset, components), ...]) for each shape of the fields."""
        self.totals = {kind: max(total, 1) for kind, total in totals.items()}

    def check_saved(self, saved: Dict[str, np.ndarray], prefix: str = ""):
        """ValueError naming the first field of the store (`prefix` + name, as a saved state
        calls it) that `saved` lacks or holds in another shape or type: `write` would cast
        silently, and an f32 state would go on in f64 (or an f64 one be rounded to f32) as no
        run did, a damaged file's integers pass for positions."""
        for name, shape in self.shapes.items():
            if name not in saved:
                raise ValueError(f"saved state has no field {prefix + name!r}")
            if saved[name].shape != shape:
                raise ValueError(f"saved state field {prefix + name!r} has shape "
                                 f"{saved[name].shape}, this engine {shape}")
            if saved[name].dtype != self.dtypes[name]:
                raise ValueError(f"saved state field {prefix + name!r} has type "
                                 f"{saved[name].dtype}, this engine {self.dtypes[name]} (another "
                                 f"precision, or a damaged file)")

    def flat_arrays(self) -> Dict[bool, np.ndarray]:
        """Zeroed packing arrays: float64 (key True) and int64 (key False)."""
        return {kind: np.zeros(self.totals[kind], dtype=np.float64 if kind else np.int64)
                for kind in (True, False)}

    def write(self, values: Dict[str, np.ndarray]):
        """Every field of the store from `values` (name -> array of the field's shape, with the
        component axes last); ValueError naming a missing or misshapen entry."""
        flats = self.flat_arrays()
        for kind, entries in self.layout.items():
            for name, offset, size in entries:
                if name not in values:
                    raise ValueError(f"no values for field {name!r}")
                array = np.asarray(values[name])
                if array.shape != self.shapes[name]:
                    raise ValueError(f"field {name!r} has shape {self.shapes[name]}, got "
                                     f"{array.shape}")
                flats[kind][offset:offset + size] = array.ravel()
        self._run_transfer(flats, True)

    def read(self) -> Dict[str, np.ndarray]:
        """Every field of the store as a NumPy array of its own dtype and shape."""
        if self.zeroed_fields:
            raise ValueError("a store with zeroed fields only writes")
        flats = self.flat_arrays()
        self._run_transfer(flats, False)
        return {name: flats[kind][offset:offset + size].reshape(self.shapes[name])
                .astype(self.dtypes[name])
                for kind, entries in self.layout.items() for name, offset, size in entries}

    def _run_transfer(self, flats: Dict[bool, np.ndarray], to_fields: bool):
        # the kernel unrolls a static loop over the fields of each shape by design (an engine's
        # load store has ~50 of one shape): Taichi's warning that a static loop of over 32
        # iterations may compile slowly is not for it
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="You are unrolling more than",
                                    category=SyntaxWarning)
            self._transfer(flats[True], flats[False], to_fields)

    @ti.func
    def _copy_element(self, field: ti.template(), index: ti.template(), flat: ti.template(),
                      start, to_field: ti.template()):
        """Element `index` (None: a 0-D field's) of `field` to or from its flat array at `start`
        (components last)."""
        components = ti.static(_components(field))
        if ti.static(len(components) == 0):
            if ti.static(to_field):
                field[index] = ti.cast(flat[start], field.dtype)
            else:
                flat[start] = field[index]
        elif ti.static(len(components) == 1):
            for k in ti.static(range(components[0])):
                if ti.static(to_field):
                    field[index][k] = ti.cast(flat[start + k], field.dtype)
                else:
                    flat[start + k] = field[index][k]
        else:
            for k, m in ti.static(ti.ndrange(components[0], components[1])):
                if ti.static(to_field):
                    field[index][k, m] = ti.cast(flat[start + k * components[1] + m],
                                                 field.dtype)
                else:
                    flat[start + k * components[1] + m] = field[index][k, m]

    @ti.func
    def _zero_element(self, field: ti.template(), index: ti.template()):
        """Element `index` (None: a 0-D field's) of `field` set to +0 (not `ti.zero`, which
        multiplies the old value by zero: -0.0 from a negative one, NaN from NaN)."""
        components = ti.static(_components(field))
        if ti.static(len(components) == 0):
            field[index] = 0
        elif ti.static(len(components) == 1):
            for k in ti.static(range(components[0])):
                field[index][k] = 0
        else:
            for k, m in ti.static(ti.ndrange(components[0], components[1])):
                field[index][k, m] = 0

    @ti.func
    def _linear(self, index, shape: ti.template()):
        """Row-major position of `index` within `shape`."""
        linear = 0
        for axis in ti.static(range(len(shape))):
            linear = linear * shape[axis] + index[axis]
        return linear

    @ti.kernel
    def _transfer(self, floats: ti.types.ndarray(dtype=ti.f64, ndim=1),
                  ints: ti.types.ndarray(dtype=ti.i64, ndim=1), to_fields: ti.template()):
        """Flat arrays -> fields (and zero into the zeroed fields) when `to_fields`, else fields
        -> flat arrays. One parallel loop per shape, which copies the element of every field of
        that shape: each loop is a function that LLVM compiles apart, and ~100 fields in ~20
        shapes compile in a fraction of the time of a loop each."""
        for shape, entries in ti.static(self.by_shape):
            for index in ti.grouped(ti.ndrange(*shape)):
                linear = self._linear(index, shape)
                for field, kind, offset, width in ti.static(entries):
                    if ti.static(kind == _FLOAT):
                        self._copy_element(field, index, floats, offset + linear * width,
                                           to_fields)
                    elif ti.static(kind == _INT):
                        self._copy_element(field, index, ints, offset + linear * width,
                                           to_fields)
                    elif ti.static(to_fields):
                        self._zero_element(field, index)
        for field, kind, offset, _ in ti.static(self.scalars):
            if ti.static(kind == _FLOAT):
                self._copy_element(field, None, floats, offset, to_fields)
            elif ti.static(kind == _INT):
                self._copy_element(field, None, ints, offset, to_fields)
            elif ti.static(to_fields):
                self._zero_element(field, None)
