"""`fields.FieldStore`: bulk copies between NumPy and an arena's fields, and the zeroed fields
a store resets on the device instead of copying. Every value is compared exactly: a store only
moves and casts values (f64 -> f64 here), so nothing may change in the last bit."""

import warnings

import numpy as np
import pytest

from taichi_star.fields import FieldArena, FieldStore


def _fields():
    """A scalar, a vector, a matrix and an integer batch field of 3 instances, in one arena."""
    arena = FieldArena()
    fields = {"scalar": arena.batch_field(float, (3, 4)),
              "vector": arena.batch_field(float, (3, 5), vector=2),
              "matrix": arena.batch_field(float, (3, 2), matrix=(2, 2)),
              "count": arena.batch_field(int, 3)}
    arena.finalize()
    return fields


def _random_values(store, seed):
    rng = np.random.default_rng(seed)
    return {name: (rng.normal(size=shape) if np.issubdtype(store.dtypes[name], np.floating)
                   else rng.integers(-9, 9, size=shape)).astype(store.dtypes[name])
            for name, shape in store.shapes.items()}


def test_a_store_writes_and_reads_back_every_field_exactly(taichi_cpu):
    store = FieldStore(_fields())
    values = _random_values(store, 0)
    store.write(values)
    back = store.read()
    for name, array in values.items():
        assert np.array_equal(back[name], array), name


def test_zeroed_fields_are_set_to_zero_and_the_others_copied(taichi_cpu):
    fields = _fields()
    full = FieldStore(fields)
    before = _random_values(full, 1)           # every field non-zero before the reset,
    before["vector"][0, 0] = (-1.0, np.nan)    # negative and NaN among them
    before["matrix"][1, 1, 0] = (np.inf, -np.inf)
    full.write(before)
    reset = FieldStore(fields, zeroed=("vector", "matrix"))
    assert set(reset.shapes) == {"scalar", "count"}   # only these are packed on the host
    copied = _random_values(reset, 2)
    reset.write(copied)
    after = full.read()
    # bytes, not values: -0.0 == 0.0, but a reset must give the +0.0 of a fresh field
    for name in ("vector", "matrix"):
        assert after[name].tobytes() == np.zeros_like(after[name]).tobytes(), name
    assert np.array_equal(after["scalar"], copied["scalar"])
    assert np.array_equal(after["count"], copied["count"])


def test_a_store_with_zeroed_fields_refuses_to_read_and_unknown_names(taichi_cpu):
    fields = _fields()
    with pytest.raises(ValueError, match="only writes"):
        FieldStore(fields, zeroed=("vector",)).read()
    with pytest.raises(ValueError, match="velocity"):
        FieldStore(fields, zeroed=("velocity",))


def test_an_arena_leaves_its_index_tables_to_the_owner_when_asked(taichi_cpu):
    # the engine writes its tables with its own load (one kernel fewer to compile): until then
    # they hold zeros, and `tables` gives each field with the values it is to hold
    arena = FieldArena()
    table = arena.index([[3, 1], [4, 1]])
    arena.finalize(fill_tables=False)
    assert not table.to_numpy().any()
    (name, (field, values)), = arena.tables().items()
    assert field is table and np.array_equal(values, [[3, 1], [4, 1]])
    FieldStore({name: field}).write({name: values})
    assert np.array_equal(table.to_numpy(), [[3, 1], [4, 1]])


def test_a_store_of_many_fields_compiles_without_taichis_unrolling_warning(taichi_cpu):
    # an engine's load store copies ~40 fields, one loop each: Taichi warns of any static loop
    # over 32 iterations, which would reach the user at every engine's first load
    arena = FieldArena()
    fields = {f"field_{number}": arena.batch_field(float, 2) for number in range(40)}
    arena.finalize()
    store = FieldStore(fields)
    values = {name: np.full(2, float(number)) for number, name in enumerate(fields)}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        store.write(values)
    assert all(np.array_equal(store.read()[name], values[name]) for name in fields)
