"""The typing rule of engine/ and app/ (issue 23 item 5): every function is annotated, except compiled kernels.

mypy runs with ``disallow_untyped_defs``; the modules that hold numba kernels are exempt in pyproject.toml
because mypy cannot tell a kernel from any other function. This test closes that gap: in every module, a
function without annotations must be a compiled kernel (decorated with ``njit``/``jit``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
KERNEL_DECORATORS = {"njit", "jit"}


def _decorator_name(node: ast.expr) -> str:
    target = node.func if isinstance(node, ast.Call) else node
    if isinstance(target, ast.Attribute):
        return target.attr
    return target.id if isinstance(target, ast.Name) else ""


def _is_annotated(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    args = fn.args
    params = [*args.posonlyargs, *args.args, *args.kwonlyargs, args.vararg, args.kwarg]
    named = [a for a in params if a is not None and a.arg not in ("self", "cls")]
    return fn.returns is not None and all(a.annotation is not None for a in named)


def untyped_non_kernels(source: str) -> list[str]:
    """Names of the functions in ``source`` that lack annotations and are not compiled kernels."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and not _is_annotated(node):
            if not {_decorator_name(d) for d in node.decorator_list} & KERNEL_DECORATORS:
                found.append(f"{node.name} (line {node.lineno})")
    return found


def test_the_checker_tells_a_kernel_from_an_untyped_function() -> None:
    src = (
        "@njit(cache=True)\ndef k(a, b):\n    return a\n\n"
        "def f(a):\n    return a\n\n"
        "def g(a: int) -> int:\n    return a\n"
    )
    assert untyped_non_kernels(src) == ["f (line 5)"]


@pytest.mark.parametrize("package", ["engine", "app"])
def test_every_function_outside_the_compiled_kernels_is_annotated(package: str) -> None:
    offenders = {
        str(path.relative_to(ROOT)): names
        for path in sorted((ROOT / package).rglob("*.py"))
        if (names := untyped_non_kernels(path.read_text(encoding="utf-8")))
    }
    assert offenders == {}
