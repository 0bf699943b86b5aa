"""`runtime.memoise_source_positions` and `runtime.memoise_function_sources`: Taichi's front end
writes each distinct source position and reads each function's source once per process, and the
texts (so its debug information and error messages) stay those it writes."""

import ast
from types import SimpleNamespace

import numpy as np
import pytest
import taichi as ti
from taichi.lang.ast import ast_transformer_utils

from taichi_star import runtime


def fake_context_class():
    """A stand-in for Taichi's context: what the key reads, and a writer that counts."""

    class Context:
        writes = 0

        def __init__(self, lines, function="g", file="f.py", lineno_offset=0, indent=0):
            self.file, self.lineno_offset, self.indent, self.src = file, lineno_offset, indent, lines
            self.func = SimpleNamespace(func=SimpleNamespace(__name__=function))

        def get_pos_info(self, node):
            Context.writes += 1
            return (f"{self.file}:{node.lineno + self.lineno_offset}:{self.func.func.__name__}:"
                    f"{self.src[node.lineno - 1]}@{self.indent + node.col_offset}")

    return Context


def statement(source, index=0):
    return ast.parse(source).body[index]


def test_each_distinct_position_is_written_once_and_read_back_unchanged():
    context = fake_context_class()
    assert runtime.memoise_source_positions(context, (1, 7, 4))
    node = statement("a = b + c")
    texts = [context(["a = b + c"]).get_pos_info(node) for _ in range(3)]
    assert texts == ["f.py:1:g:a = b + c@0"] * 3
    assert context.writes == 1


@pytest.mark.parametrize("node, lines, where, expected", [
    ("a = b + c", ["a = b + d"], {}, "f.py:1:g:a = b + d@0"),  # another source line
    ("a = b + c", ["a = b + c"], {"function": "h"}, "f.py:1:h:a = b + c@0"),
    ("a = b + c", ["a = b + c"], {"file": "e.py"}, "e.py:1:g:a = b + c@0"),
    ("a = b + c", ["a = b + c"], {"lineno_offset": 4}, "f.py:5:g:a = b + c@0"),
    ("a = b + c", ["a = b + c"], {"indent": 8}, "f.py:1:g:a = b + c@8"),
    ("a = (b + c)", ["a = b + c"], {}, "f.py:1:g:a = b + c@0"),  # another span
])
def test_a_position_that_differs_in_anything_it_is_made_of_is_written_again(node, lines, where,
                                                                          expected):
    context = fake_context_class()
    runtime.memoise_source_positions(context, (1, 7, 4))
    context(["a = b + c"]).get_pos_info(statement("a = b + c"))
    assert context(lines, **where).get_pos_info(statement(node)) == expected
    assert context.writes == 2


def test_the_cache_keeps_up_to_its_size_then_starts_afresh(monkeypatch):
    monkeypatch.setattr(runtime, "SOURCE_POSITIONS_KEPT", 2)
    context = fake_context_class()
    runtime.memoise_source_positions(context, (1, 7, 4))
    lines = ["a = 1", "b = 2", "c = 3"]
    first, second, third = (statement("\n".join(lines), i) for i in range(3))
    for node in (first, second, first):  # two kept: the third ask is a hit
        context(lines).get_pos_info(node)
    assert context.writes == 2
    context(lines).get_pos_info(third)   # a third distinct one: the two are dropped
    context(lines).get_pos_info(first)
    assert context.writes == 4


@pytest.mark.parametrize("memoise, make_target, attribute, make_lacking", [
    (runtime.memoise_source_positions, fake_context_class, "get_pos_info",
     lambda: type("NoWriter", (), {})),
    (runtime.memoise_function_sources, lambda: fake_readers()[0], "getsourcelines",
     lambda: SimpleNamespace(getsourcelines=lambda function: ([], 0))),  # no getsourcefile
], ids=["positions", "sources"])
def test_installed_once_only_for_the_checked_taichi_and_only_where_its_target_exists(
        memoise, make_target, attribute, make_lacking):
    target = make_target()
    original = getattr(target, attribute)
    assert not memoise(target, (1, 8, 0))
    assert getattr(target, attribute) is original
    assert memoise(target, (1, 7, 0))
    memoised = getattr(target, attribute)
    assert memoised is not original and memoised.unmemoised is original
    assert memoise(target, (1, 7, 4))  # a second call: the same memo
    assert getattr(target, attribute) is memoised
    lacking = make_lacking()
    assert not memoise(lacking, (1, 7, 4))



@ti.func
def clipped_sum(values: ti.template(), count):
    total = 0.0
    for i in range(count):
        if values[i] > 0.0:
            total += (values[i]
                      * 2.0)
        else:
            total -= values[i]
    while total > 10.0:
        total -= 1.0
    return total


def test_taichis_own_texts_are_unchanged_on_a_real_compile(monkeypatch):
    """Every position asked for while compiling a kernel that inlines one function (a loop, a
    branch, a statement over two lines, a while) three times equals the original writer's."""
    runtime.Runtime.current().ensure("cpu", "f64")  # installs the memo
    memoised = ast_transformer_utils.ASTTransformerContext.get_pos_info
    assert hasattr(memoised, "unmemoised")
    pairs = []

    def checking(context, node):
        text = memoised(context, node)
        pairs.append((text, memoised.unmemoised(context, node)))
        return text

    monkeypatch.setattr(ast_transformer_utils.ASTTransformerContext, "get_pos_info", checking)
    values = ti.field(ti.f64, shape=4)

    @ti.kernel
    def three_sums() -> ti.f64:
        return clipped_sum(values, 4) + clipped_sum(values, 3) + clipped_sum(values, 2)

    values.from_numpy(np.array([1.0, -2.0, 3.0, 7.0]))
    # 2·(1 + 3 + 7) + 2 = 24, brought down to 10 by the while; 2·(1 + 3) + 2 = 10; 2·1 + 2 = 4
    assert three_sums() == 24.0
    assert len(pairs) > 100 and any("^" in text for text, _ in pairs)
    assert [memo for memo, _ in pairs] == [written for _, written in pairs]
    assert len(set(pairs)) < len(pairs)  # the function's positions were asked for again


def broken_kernel():
    @ti.kernel
    def broken() -> ti.f64:
        total = 0.0
        for i in range(3):
            total += name_that_is_not_defined * i  # noqa: F821
        return total

    return broken


def test_a_compile_error_reads_as_without_the_memo(monkeypatch):
    runtime.Runtime.current().ensure("cpu", "f64")
    with pytest.raises(Exception) as memoised_error:
        broken_kernel()()
    memoised = ast_transformer_utils.ASTTransformerContext.get_pos_info
    monkeypatch.setattr(ast_transformer_utils.ASTTransformerContext, "get_pos_info",
                        memoised.unmemoised)
    with pytest.raises(Exception) as original_error:
        broken_kernel()()
    assert type(memoised_error.value) is type(original_error.value)
    assert str(memoised_error.value) == str(original_error.value)
    assert "name_that_is_not_defined" in str(memoised_error.value)
    assert "^" in str(memoised_error.value)  # the excerpt with its caret line is there


def fake_readers():
    """A stand-in for Taichi's `kernel_impl`: source readers that count their reads."""
    reads = []

    def getsourcelines(function):
        reads.append(function)
        return [f"def {function.__name__}():\n", f"    return {function()}\n"], 7

    def getsourcefile(function):
        reads.append(function)
        return f"{function.__name__}.py"

    return SimpleNamespace(getsourcelines=getsourcelines, getsourcefile=getsourcefile), reads


def test_each_functions_source_is_read_once_and_handed_out_as_a_copy():
    module, reads = fake_readers()
    assert runtime.memoise_function_sources(module, (1, 7, 4))

    def one():
        return 1

    first = module.getsourcelines(one)
    assert first == (["def one():\n", "    return 1\n"], 7)
    first[0].append("changed by the caller\n")
    assert module.getsourcelines(one) == (["def one():\n", "    return 1\n"], 7)
    assert module.getsourcefile(one) == module.getsourcefile(one) == "one.py"
    assert reads == [one, one]  # one read per reader


def test_another_function_or_another_code_object_is_read_again():
    module, reads = fake_readers()
    runtime.memoise_function_sources(module, (1, 7, 4))

    def one():
        return 1

    def two():
        return 2

    module.getsourcelines(one)
    assert module.getsourcelines(two)[0][1] == "    return 2\n"
    one.__code__ = two.__code__  # what a reloading tool does to a function it keeps
    assert module.getsourcelines(one)[0][1] == "    return 2\n"
    assert reads == [one, two, one]


def test_a_function_that_cannot_be_held_weakly_is_read_every_time():
    module, reads = fake_readers()
    runtime.memoise_function_sources(module, (1, 7, 4))

    class Unreferable:  # __slots__ without __weakref__: no weak reference can be made
        __slots__ = ()
        __name__ = "unreferable"

        def __call__(self):
            return 3

    unreferable = Unreferable()
    assert module.getsourcelines(unreferable) == (["def unreferable():\n", "    return 3\n"], 7)
    assert module.getsourcelines(unreferable) == (["def unreferable():\n", "    return 3\n"], 7)
    assert len(reads) == 2


def test_taichis_reads_go_through_the_memo_and_its_compiles_and_errors_are_unchanged(
        monkeypatch):
    """After the runtime started, Taichi's front end reads through the memo. A memo over
    counting readers in its place: a kernel that inlines one function three times computes the
    right value with that function's source read once, and a compile error's message is the
    one Taichi gives without the memo."""
    from taichi.lang import kernel_impl

    runtime.Runtime.current().ensure("cpu", "f64")
    installed = (kernel_impl.getsourcelines, kernel_impl.getsourcefile)
    assert all(hasattr(reader, "unmemoised") for reader in installed)
    reads = []

    def counting(read):
        return lambda function: reads.append(function.__name__) or read(function)

    readers = SimpleNamespace(getsourcelines=counting(installed[0].unmemoised),
                              getsourcefile=counting(installed[1].unmemoised))
    runtime.memoise_function_sources(readers, (1, 7, 4))
    monkeypatch.setattr(kernel_impl, "getsourcelines", readers.getsourcelines)
    monkeypatch.setattr(kernel_impl, "getsourcefile", readers.getsourcefile)
    values = ti.field(ti.f64, shape=4)

    @ti.kernel
    def three_sums() -> ti.f64:
        return clipped_sum(values, 4) + clipped_sum(values, 3) + clipped_sum(values, 2)

    values.from_numpy(np.array([1.0, -2.0, 3.0, 7.0]))
    assert three_sums() == 24.0  # 10 + 10 + 4, as in the positions' test above
    assert reads.count("clipped_sum") == 2    # its lines once and its file once
    assert reads.count("three_sums") == 2
    with pytest.raises(Exception) as memoised_error:
        broken_kernel()()
    monkeypatch.setattr(kernel_impl, "getsourcelines", installed[0].unmemoised)
    monkeypatch.setattr(kernel_impl, "getsourcefile", installed[1].unmemoised)
    with pytest.raises(Exception) as original_error:
        broken_kernel()()
    assert str(memoised_error.value) == str(original_error.value)
    assert "name_that_is_not_defined" in str(memoised_error.value)
