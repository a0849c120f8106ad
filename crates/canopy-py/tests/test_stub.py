"""The type stub `_canopy.pyi` against the native module it describes: every public
function and class of the module is in the stub, and every function and method in the
stub takes the parameters, by name and in order, that the native one takes (as its
`__text_signature__` gives them). The stub is written by hand; this is what keeps it
true when a native signature changes."""

import ast
import pathlib

import canopy_rt
import canopy_rt._canopy as native

STUB = pathlib.Path(canopy_rt.__file__).with_name("_canopy.pyi")


def stub_parameters(function: ast.FunctionDef) -> list:
    args = function.args
    return [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs if a.arg != "self"]


def native_parameters(text_signature: str) -> list:
    names = []
    for part in text_signature.strip("()").split(","):
        name = part.split("=")[0].strip()
        if name in ("", "/", "*", "$self", "$type"):
            continue
        names.append(name.lstrip("*"))
    return names


def is_property(function: ast.FunctionDef) -> bool:
    return any(isinstance(d, ast.Name) and d.id == "property" for d in function.decorator_list)


def stubbed():
    """(qualified name, stub function, native object) of every function in the stub."""
    for node in ast.parse(STUB.read_text()).body:
        if isinstance(node, ast.FunctionDef):
            yield node.name, node, getattr(native, node.name, None)
        elif isinstance(node, ast.ClassDef):
            cls = getattr(native, node.name, None)
            assert cls is not None, f"the stub's class {node.name} is not in the native module"
            for f in node.body:
                if isinstance(f, ast.FunctionDef) and not is_property(f):
                    # A class's constructor signature is the class's own.
                    obj = cls if f.name == "__init__" else getattr(cls, f.name, None)
                    yield f"{node.name}.{f.name}", f, obj


def test_the_stub_names_every_public_native_function_and_class():
    in_stub = {n.name for n in ast.parse(STUB.read_text()).body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    public = {name for name in dir(native) if not name.startswith("_") and callable(getattr(native, name))}
    assert public - in_stub == set()


def test_the_stub_takes_the_native_parameters():
    wrong = []
    for name, function, obj in stubbed():
        assert obj is not None, f"the stub's {name} is not in the native module"
        signature = getattr(obj, "__text_signature__", None)
        assert signature is not None, f"{name} has no native signature to compare"
        if stub_parameters(function) != native_parameters(signature):
            wrong.append(f"{name}: stub {stub_parameters(function)}, native {native_parameters(signature)}")
    assert wrong == []
