"""Build a Python block into an FMU with pythonfmu, and fix what ``fmpy validate`` flags in it.

pythonfmu 0.7 writes a model description that fmpy's validator rejects or that says less than the
block declares:

* ``ModelStructure/InitialUnknowns`` is missing: every output with ``initial="calculated"`` must be
  listed there (fmpy: *"InitialUnknowns does not contain the expected set of variables"*);
* variables without an explicit variability default to ``continuous``, an illegal combination for
  parameters and for Integer / Boolean variables; ``initial`` is left to defaults;
* pythonfmu has no units at all: the declared units are added to the Real variables and every unit
  used is declared in ``UnitDefinitions`` (fmpy: *"The unit ... is not defined"*).

:func:`fix_model_description` repairs these on any pythonfmu description (not only
:class:`~pendulab.blocks.base.Block` ones); :func:`build_block` builds, repairs, checks the result
with ``fmpy.validation.validate_fmu`` and writes the FMU atomically.

Examples
--------
>>> from pendulab.blocks import build_block
>>> # skipped: the files are yours (build_block's own example builds one)
>>> fmu = build_block("gain.py", "fmus/")                                  # doctest: +SKIP
>>> fmu = build_block(LQRController, "fmus/", start_values={"K_x": -10})   # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import json
import math
import os
import re
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pythonfmu import Fmi2Slave

from pendulab.blocks.base import START_VALUES_FILE, Block
from pendulab.errors import FmuBuildError, UserError

#: Children of fmiModelDescription in schema order (UnitDefinitions must go to its place).
_ELEMENT_ORDER = (
    "ModelExchange", "CoSimulation", "UnitDefinitions", "TypeDefinitions", "LogCategories",
    "DefaultExperiment", "VendorAnnotations", "ModelVariables", "ModelStructure",
)
_TYPE_TAGS = ("Real", "Integer", "Boolean", "String", "Enumeration")
_DEFAULT_START = {"Real": "0", "Integer": "0", "Boolean": "false", "String": "", "Enumeration": "1"}


def build_block(
    block: type[Fmi2Slave] | str | Path,
    out: str | Path = ".",
    *,
    start_values: Mapping[str, Any] | None = None,
    validate: bool = True,
) -> Path:
    """Build a block class into ``<out>/<ClassName>.fmu`` (FMI 2.0 Co-Simulation, pythonfmu).

    Parameters
    ----------
    block : Block subclass, or path of a ``.py`` file
        A class (importable from its module), or a file that defines exactly one block class.
        The file must be self-contained: it may import installed packages (pendulab, numpy),
        not sibling files.
    out : path
        Folder for the FMU, or the FMU's file name (``.../Name.fmu``).
    start_values : mapping, optional
        New defaults for parameters and inputs, baked into the FMU (model description and the
        instance's start values), e.g. the gains of a controller design.
    validate : bool
        Check the result with ``fmpy.validation.validate_fmu`` (raises FmuBuildError on a problem).

    Returns
    -------
    Path
        The FMU. It runs where Python with pythonfmu and pendulab is loaded (e.g. pendulab's master,
        fmpy): pythonfmu FMUs call back into the host's Python interpreter.

    Raises
    ------
    UserError
        The file or class is not a usable block, or a start value names no parameter or input.

    Examples
    --------
    >>> import tempfile
    >>> from pendulab.blocks.lqr import LQRController
    >>> fmu = build_block(LQRController, tempfile.mkdtemp(), start_values={"K_x": -10.0})
    >>> fmu.name
    'LQRController.fmu'
    """
    cls, copies = _resolve(block)
    starts = _check_start_values(cls, start_values or {})
    target = Path(out)
    if target.suffix != ".fmu":
        target = target / f"{cls.__name__}.fmu"
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create the output folder {target.parent}: {exc.strerror or exc}; choose another folder") from None

    with tempfile.TemporaryDirectory(prefix="pendulab-block-") as tmp:
        staging = Path(tmp) / "src"
        staging.mkdir()
        project_files = []
        for module_name, text in copies.items():
            (staging / f"{module_name}.py").write_text(text)
            project_files.append(staging / f"{module_name}.py")
        shim_text = _shim(cls, copies)
        shim_name = "pendulab_block_" + hashlib.sha256(shim_text.encode() + "".join(copies.values()).encode()).hexdigest()[:12]
        shim = staging / f"{shim_name}.py"
        shim.write_text(shim_text)
        built = _run_pythonfmu(shim, Path(tmp) / "out", project_files, [shim_name, *copies], cls)

        units = cls.units() if issubclass(cls, Block) else {}
        fd, partial = tempfile.mkstemp(dir=target.parent, prefix=f".{target.stem}-", suffix=".fmu.part")
        os.close(fd)
        try:
            _rewrite_zip(built, Path(partial), units, starts)
            if validate:
                from fmpy.validation import validate_fmu

                problems = validate_fmu(partial)
                if problems:
                    raise FmuBuildError(f"{target.name} fails fmpy validate after patching: " + "; ".join(problems))
            os.replace(partial, target)
        finally:
            if os.path.exists(partial):
                os.remove(partial)
    return target


# ---------------------------------------------------------------------- finding the class
def _resolve(block: type[Fmi2Slave] | str | Path) -> tuple[type[Fmi2Slave], dict[str, str]]:
    """The block class, and the source files to ship (module name -> text) when it is not importable."""
    if isinstance(block, type):
        _check_class(block, repr(block.__name__))
        module = sys.modules.get(block.__module__)
        if block.__module__ != "__main__" and module is not None and getattr(module, block.__name__, None) is block:
            try:
                spec = importlib.util.find_spec(block.__module__)
            except (ImportError, ValueError):
                spec = None
            if spec is not None and spec.origin == getattr(module, "__file__", None):
                return block, {}
        source = inspect.getsourcefile(block)
        if source is None:
            raise UserError(f"cannot find the source file of {block.__name__}; define it in a .py file")
        cls, copies = _resolve_file(Path(source), block.__name__)
        return cls, copies
    return _resolve_file(Path(block), None)


def _resolve_file(path: Path, class_name: str | None) -> tuple[type[Fmi2Slave], dict[str, str]]:
    if path.suffix != ".py":
        raise UserError(f"block file {path} must be a Python file ending in .py")
    try:
        text = path.read_text()
    except OSError as exc:
        raise UserError(f"cannot read block file {path}: {exc.strerror or exc}") from None
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    stem = re.sub(r"\W", "_", path.stem)
    module_name = f"{stem}_{digest}"
    probe = f"_pendulab_probe_{module_name}"
    spec = importlib.util.spec_from_file_location(probe, path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    sys.modules[probe] = module
    try:
        spec.loader.exec_module(module)  # type: ignore[union-attr]
    except UserError:
        raise
    except Exception as exc:  # noqa: BLE001 - any error in the user's file is reported as theirs
        raise UserError(f"block file {path} does not import: {type(exc).__name__}: {exc}") from None
    finally:
        sys.modules.pop(probe, None)
    found = [
        obj for obj in vars(module).values()
        if isinstance(obj, type) and issubclass(obj, Fmi2Slave) and obj.__module__ == probe and not inspect.isabstract(obj)
    ]
    if class_name is not None:
        found = [c for c in found if c.__name__ == class_name]
    if not found:
        raise UserError(f"{path} defines no block class; subclass pendulab.blocks.Block and implement step(t, h)")
    if len(found) > 1:
        names = ", ".join(c.__name__ for c in found)
        raise UserError(f"{path} defines several block classes ({names}); keep one block per file")
    return found[0], {module_name: text}


def _check_class(cls: type, label: str) -> None:
    if not issubclass(cls, Fmi2Slave):
        raise UserError(f"{label} is not a block; subclass pendulab.blocks.Block")
    if inspect.isabstract(cls):
        missing = ", ".join(sorted(getattr(cls, "__abstractmethods__", ())))
        raise UserError(f"{label} is abstract: implement {missing}")


def _shim(cls: type, copies: Mapping[str, str]) -> str:
    """The FMU's entry module: imports just the one class, so pythonfmu cannot pick another.

    pythonfmu 0.7's loader (``findClass`` in its binary) re-executes the entry module's source in the
    module's namespace at every instantiation and then releases a reference to that namespace it
    never took (``Py_DECREF`` of the borrowed ``PyModule_GetDict``). Unbalanced, the namespace is
    freed after a few instances and the next instantiation fails ("module has no attribute") or
    crashes the process. The pin line adds one reference per execution to balance it: a bare
    ``Py_IncRef``, not a container holding the namespace, since the garbage collector must not see
    more referrers than the reference count says (it would then free the namespace and crash).
    """
    module = next(iter(copies)) if copies else cls.__module__
    return (
        f'"""Entry module of the {cls.__name__} FMU (generated by pendulab.blocks.build)."""\n'
        "# Balances the reference pythonfmu 0.7's loader drops on every instantiation (see pendulab.blocks.build._shim).\n"
        "import ctypes as _ctypes\n"
        "_ctypes.pythonapi.Py_IncRef(_ctypes.py_object(globals()))\n"
        f"from {module} import {cls.__name__}\n"
    )


def _check_start_values(cls: type[Fmi2Slave], start_values: Mapping[str, Any]) -> dict[str, Any]:
    if not start_values:
        return {}
    if not issubclass(cls, Block):
        raise UserError(f"start values need a pendulab Block; {cls.__name__} is a plain pythonfmu slave")
    table = cls.variables()
    settable = [n for n, (causality, _) in table.items() if causality != "output"]
    result = {}
    for name, value in start_values.items():
        if name not in settable:
            raise UserError(f"{cls.__name__} has no parameter or input {name!r}; choose from {', '.join(settable)}")
        result[name] = table[name][1].coerce(value, f"{cls.__name__}.{name}")
    return result


# ---------------------------------------------------------------------- pythonfmu
def _run_pythonfmu(script: Path, out_dir: Path, project_files: list[Path], modules: list[str], cls: type) -> Path:
    from pythonfmu import FmuBuilder

    saved_path = list(sys.path)
    for name in modules:
        sys.modules.pop(name, None)
    try:
        built = Path(FmuBuilder.build_FMU(script, dest=out_dir, project_files=project_files))
    except (UserError, FmuBuildError):
        raise
    except Exception as exc:  # noqa: BLE001 - pythonfmu runs the user's class; report its error
        raise UserError(f"pythonfmu cannot build {cls.__name__}: {type(exc).__name__}: {exc}") from None
    finally:
        # pythonfmu leaves the script's folder on sys.path and the module imported.
        sys.path[:] = saved_path
        for name in modules:
            sys.modules.pop(name, None)
    return built


def _rewrite_zip(source: Path, target: Path, units: Mapping[str, str], start_values: Mapping[str, Any]) -> None:
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = fix_model_description(data, units=units, start_values=start_values)
            zout.writestr(item.filename, data)
        if start_values:
            zout.writestr(f"resources/{START_VALUES_FILE}", json.dumps(start_values, indent=1))


# ---------------------------------------------------------------------- the model description
def fix_model_description(
    xml: bytes | str,
    *,
    units: Mapping[str, str] | None = None,
    start_values: Mapping[str, Any] | None = None,
) -> bytes:
    """Repair a pythonfmu ``modelDescription.xml`` so that ``fmpy validate`` accepts it.

    Parameters
    ----------
    units : mapping, optional
        Variable name -> unit to put on Real variables; every unit used gets a ``UnitDefinitions`` entry.
    start_values : mapping, optional
        Variable name -> new start value.

    Examples
    --------
    >>> xml = '''<fmiModelDescription fmiVersion="2.0" modelName="G" guid="1">
    ...   <CoSimulation modelIdentifier="G"/>
    ...   <ModelVariables>
    ...     <ScalarVariable name="y" valueReference="0" causality="output"><Real/></ScalarVariable>
    ...     <ScalarVariable name="k" valueReference="1" causality="parameter"><Real start="2"/></ScalarVariable>
    ...   </ModelVariables>
    ...   <ModelStructure><Outputs><Unknown index="1"/></Outputs></ModelStructure>
    ... </fmiModelDescription>'''
    >>> fixed = fix_model_description(xml, units={"y": "V"}).decode()
    >>> '<InitialUnknowns>' in fixed and '<Unit name="V" />' in fixed and 'variability="fixed"' in fixed
    True
    """
    units = dict(units or {})
    start_values = dict(start_values or {})
    root = ET.fromstring(xml.encode() if isinstance(xml, str) else xml)
    model_variables = root.find("ModelVariables")
    variables = list(model_variables) if model_variables is not None else []
    used_units: list[str] = []

    for sv in variables:
        type_el = next((child for child in sv if child.tag in _TYPE_TAGS), None)
        if type_el is None:
            continue
        name, vtype = sv.get("name", ""), type_el.tag
        causality = sv.get("causality", "local")
        variability, initial = _legal_variability_initial(causality, sv.get("variability"), sv.get("initial"), vtype)
        sv.set("causality", causality)
        sv.set("variability", variability)
        if initial is None:
            sv.attrib.pop("initial", None)
        else:
            sv.set("initial", initial)
        if name in start_values:
            type_el.set("start", _literal(start_values[name]))
        needs_start = initial in ("exact", "approx") or causality == "input" or variability == "constant"
        if initial == "calculated":
            type_el.attrib.pop("start", None)
        elif needs_start and type_el.get("start") is None:
            type_el.set("start", _DEFAULT_START[vtype])
        if vtype == "Real":
            if name in units:
                type_el.set("unit", units[name])
            unit = type_el.get("unit")
            if unit and unit not in used_units:
                used_units.append(unit)

    _declare_units(root, used_units)
    _rebuild_model_structure(root, variables)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _legal_variability_initial(causality: str, variability: str | None, initial: str | None, vtype: str) -> tuple[str, str | None]:
    """The nearest legal FMI 2.0 (variability, initial) for a causality (spec table p. 49)."""
    changing = "continuous" if vtype == "Real" else "discrete"
    if variability == "continuous" and vtype != "Real":
        variability = "discrete"
    if causality in ("parameter", "structuralParameter"):
        return (variability if variability in ("fixed", "tunable") else "fixed"), "exact"
    if causality == "calculatedParameter":
        return (variability if variability in ("fixed", "tunable") else "fixed"), (initial if initial in ("approx", "calculated") else "calculated")
    if causality == "input":
        return (variability if variability in ("discrete", "continuous") else changing), None
    if causality == "independent":
        return "continuous", None
    # output or local
    if variability == "constant":
        return "constant", "exact"
    if causality == "output" and variability not in ("discrete", "continuous"):
        variability = changing
    variability = variability or changing
    if initial not in ("exact", "approx", "calculated"):
        initial = "calculated"
    if variability in ("fixed", "tunable") and initial == "exact":
        initial = "calculated"
    return variability, initial


def _literal(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    value = float(value)
    if not math.isfinite(value):
        raise UserError(f"start value {value} is not finite")
    return f"{value:.17g}"


def _declare_units(root: ET.Element, used: list[str]) -> None:
    definitions = root.find("UnitDefinitions")
    declared = {u.get("name") for u in definitions.findall("Unit")} if definitions is not None else set()
    missing = [u for u in used if u not in declared]
    if not missing:
        return
    if definitions is None:
        definitions = ET.Element("UnitDefinitions")
        position = _ELEMENT_ORDER.index("UnitDefinitions")
        index = sum(1 for child in root if child.tag in _ELEMENT_ORDER[:position])
        root.insert(index, definitions)
    for unit in missing:
        ET.SubElement(definitions, "Unit", name=unit)


def _rebuild_model_structure(root: ET.Element, variables: list[ET.Element]) -> None:
    """Outputs: every output; InitialUnknowns: outputs computed at initialization (FMI 2.0 §2.2.8)."""
    old = root.find("ModelStructure")
    kept: dict[tuple[str, str], ET.Element] = {}
    if old is not None:
        for section in old:
            for unknown in section.findall("Unknown"):
                kept[(section.tag, unknown.get("index", ""))] = unknown
        root.remove(old)
    structure = ET.SubElement(root, "ModelStructure")
    outputs = [i for i, sv in enumerate(variables, 1) if sv.get("causality") == "output"]
    initial_unknowns = [
        i for i, sv in enumerate(variables, 1)
        if (sv.get("causality") == "output" and sv.get("initial") in ("approx", "calculated"))
        or sv.get("causality") == "calculatedParameter"
    ]
    for tag, indices in (("Outputs", outputs), ("InitialUnknowns", initial_unknowns)):
        if not indices:
            continue
        section = ET.SubElement(structure, tag)
        for index in indices:
            section.append(kept.get((tag, str(index)), ET.Element("Unknown", index=str(index))))
    # Derivatives (Model Exchange) are not written by pythonfmu; keep them if someone added them.
    if old is not None and old.find("Derivatives") is not None:
        structure.insert(1 if structure.find("Outputs") is not None else 0, old.find("Derivatives"))
