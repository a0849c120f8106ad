"""Errors that name the argument at fault, for integers the native module cannot hold.

canopy's native functions take unsigned integers (sizes, counts, indices, seeds). A
negative or too large Python int reaches them as an ``OverflowError`` that names no
argument ("can't convert negative int to unsigned"). Every public function and method
is wrapped by :func:`naming_arguments`, which turns that error into a ``ValueError``
naming the argument and its value.
"""

from __future__ import annotations

import functools
import inspect
import numbers
from typing import Callable, Optional, Tuple, TypeVar

_F = TypeVar("_F", bound=Callable)

# The widest unsigned integer a native argument takes (seeds are 64-bit, most are 32).
_U32_END = 1 << 32
_U64_END = 1 << 64


def _whole_numbers(value):
    """The integers in an argument: itself, or those of a tuple or list of them."""
    if isinstance(value, bool):
        return
    if isinstance(value, numbers.Integral):
        yield int(value)
    elif isinstance(value, (tuple, list)) and len(value) <= 16:
        for item in value:
            yield from _whole_numbers(item)


def _fault(value) -> Optional[Tuple[int, str]]:
    """What is wrong with an argument's integers, and how surely that overflowed: a
    negative number always does, one past 64 bits always does, one past 32 bits does
    where the argument is 32-bit."""
    found = list(_whole_numbers(value))
    if any(n < 0 for n in found):
        return 0, "must not be negative"
    if any(n >= _U64_END for n in found):
        return 1, f"is too large (at most {_U64_END - 1})"
    if any(n >= _U32_END for n in found):
        return 2, f"is too large (at most {_U32_END - 1} here)"
    return None


def _blame(signature: inspect.Signature, args, kwargs) -> Optional[str]:
    """The argument an OverflowError came from, named with its fault."""
    try:
        bound = signature.bind(*args, **kwargs)
    except TypeError:
        return None
    faults = []
    for name, value in bound.arguments.items():
        fault = _fault(value)
        if fault is not None:
            faults.append((fault[0], f"{name}={value!r} {fault[1]}"))
    return min(faults)[1] if faults else None


def naming_arguments(function: _F) -> _F:
    """``function``, raising ``ValueError`` that names the argument where a negative or
    too large integer would raise an anonymous ``OverflowError``."""
    signature = inspect.signature(function)

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        try:
            return function(*args, **kwargs)
        except OverflowError as error:
            blame = _blame(signature, args, kwargs)
            if blame is None:
                raise
            raise ValueError(blame) from error

    return wrapper  # type: ignore[return-value]


def naming_arguments_of_methods(cls):
    """A class whose public methods (and ``__init__``) are wrapped by
    :func:`naming_arguments`."""
    for name, member in list(vars(cls).items()):
        public = not name.startswith("_") or name == "__init__"
        if public and inspect.isfunction(member):
            setattr(cls, name, naming_arguments(member))
        elif public and isinstance(member, staticmethod):
            setattr(cls, name, staticmethod(naming_arguments(member.__func__)))
        elif public and isinstance(member, classmethod):
            setattr(cls, name, classmethod(naming_arguments(member.__func__)))
    return cls
