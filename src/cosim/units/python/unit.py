"""Units written in Python.

Write a unit by subclassing :class:`PythonUnit`, listing its ``variables`` and
implementing ``do_step``.  Every variable becomes an attribute of the instance
holding its current value (a float, int, bool or str for scalars, a numpy array
for arrays), so a step reads ``self.tau`` and writes ``self.power``::

    class Gain(PythonUnit):
        variables = (
            Variable("k", "parameter", start=2.0),
            Variable("u", "input", start=0.0),
            Variable("y", "output", start=0.0),
        )
        def do_step(self, t, h):
            self.y = self.k * self.u

A spec names such a class as ``"python": "package.module:Gain"`` or
``"python": "file.py:Gain"`` (relative to the spec's folder).

A unit that reads files names the String parameters holding their paths in
``data_files`` (e.g. ``data_files = ("plant_file",)``): a relative path is
then read from the spec's folder, and a sweep ships the file with the unit
to workers that do not share the client's filesystem
(:mod:`cosim.units.python.data_files`).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import pickle
import sys
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar, Mapping, Sequence

import numpy as np

from cosim.units.protocol import (
    ElementRef,
    Selection,
    SimulationEnded,
    Unit,
    UnitDescription,
    UnitError,
    UnitType,
    Variable,
)
from cosim.units.python.data_files import pack, unpack
from cosim.units.python.import_guard import enter_checking_child, guarded_import, import_in_child_first


class _AttributeSelection(Selection):
    """Elements compiled into runs: a scalar attribute, or a contiguous slice of an array.

    Reading a whole array is one ``tolist()`` instead of one call per element.
    """

    def __init__(self, refs: Sequence[ElementRef], array_names: set[str]):
        self.refs = tuple(refs)
        runs: list[list[Any]] = []  # [name, first offset, last offset + 1] or [name, None, None]
        for r in refs:
            if r.variable not in array_names:
                runs.append([r.variable, None, None])
            elif runs and runs[-1][0] == r.variable and runs[-1][2] == r.offset:
                runs[-1][2] += 1
            else:
                runs.append([r.variable, r.offset, r.offset + 1])
        self.runs = tuple((name, None if a is None else slice(a, b), 0 if a is None else b - a)
                          for name, a, b in runs)
        # a vectorised twin's (K, n) result array for this selection, made at its first get (units/python/batch.py)
        self.buffer: np.ndarray | None = None


class PythonUnit(Unit):
    """Base class of units written in Python (see the module docstring).

    Subclasses set ``variables`` and may set ``feedthrough`` (output name to
    the inputs it reads directly, see :class:`UnitDescription`; default: no
    direct feed-through), ``can_reset`` and ``data_files`` (names of String
    parameters whose values are paths of files the unit reads; by the time
    ``initialize()`` runs they hold a path that can be opened here, see the
    module docstring).  Hooks a subclass may override:
    ``initialize()`` (parameters and start values are set, runs once before the
    first step), ``do_step(t, h)``, ``compute_outputs()`` (only for units with
    direct feed-through: recompute outputs from the current inputs),
    ``close()`` (free resources) and ``get_state()``/``set_state(state)``
    (defining both makes the unit's state restorable, see :meth:`get_state`).
    """

    variables: ClassVar[Sequence[Variable]] = ()
    feedthrough: ClassVar[Mapping[str, Sequence[str]]] = {}
    can_reset: ClassVar[bool] = True
    unit_description: ClassVar[str] = ""
    data_files: ClassVar[Sequence[str]] = ()
    _data_paths: Mapping[str, str] = {}  # a data-file parameter's value as given -> the file to open (set by the type)

    def __init__(self, name: str = "unit"):
        self.name = name
        self.description = self.describe_class()
        self._arrays = {v.name for v in self.description.variables if v.is_array}
        self._has_feedthrough = any(self.description.feedthrough.get(o.name) for o in self.description.outputs())
        self._outputs_stale = False
        self.start_time = 0.0
        self.stop_time: float | None = None
        self._apply_start_values()

    @classmethod
    def describe_class(cls) -> UnitDescription:
        """The description of this class's variables and capabilities.

        Raises TypeError when ``data_files`` names anything but a String parameter.
        """
        strings = {v.name for v in cls.variables if v.causality == "parameter" and v.type == "String"}
        wrong = [name for name in cls.data_files if name not in strings]
        if wrong or isinstance(cls.data_files, str):
            raise TypeError(f"{cls.__name__}.data_files must list names of its String parameters (paths of the "
                            f"files it reads); {wrong or cls.data_files!r} are not")
        declared = {k: tuple(v) for k, v in cls.feedthrough.items()}
        feedthrough = {v.name: declared.get(v.name, ()) for v in cls.variables if v.causality == "output"}
        return UnitDescription(
            name=cls.__name__,
            variables=tuple(cls.variables),
            kind="python",
            can_reset=cls.can_reset,
            feedthrough=feedthrough,
            description=cls.unit_description or (cls.__doc__ or "").strip().split("\n")[0],
            source=f"{cls.__module__}:{cls.__qualname__}",
        )

    def _apply_start_values(self) -> None:
        for v in self.description.variables:
            if v.is_array:
                dtype = {"Real": float, "Integer": np.int64, "Boolean": bool}.get(v.type, object)
                start = v.start if v.start is not None else 0
                value = np.array(start, dtype=dtype).reshape(-1) if np.ndim(start) else np.full(v.size, start, dtype=dtype)
                if value.size != v.size:
                    raise UnitError(self.name, f"start value of '{v.name}' has {value.size} elements, expected {v.size}")
                setattr(self, v.name, value.copy())
            else:
                default = {"Real": 0.0, "Integer": 0, "Boolean": False, "String": ""}[v.type]
                setattr(self, v.name, v.start if v.start is not None else default)

    # Protocol ------------------------------------------------------------

    def select(self, refs: Sequence[ElementRef]) -> Selection:
        return _AttributeSelection(refs, self._arrays)

    def get(self, selection: Selection) -> list[Any]:
        if self._outputs_stale:
            self._outputs_stale = False
            self._call("compute_outputs", None)
        out: list[Any] = []
        # attr-defined: the protocol hands back the Selection this unit's select() made, an _AttributeSelection
        for name, part, _ in selection.runs:  # type: ignore[attr-defined]
            value = getattr(self, name)
            if part is None:
                out.append(value)
            else:
                out.extend(value[part].tolist())
        return out

    def set(self, selection: Selection, values: Sequence[Any]) -> None:
        i = 0
        for name, part, n in selection.runs:  # type: ignore[attr-defined]  # as in get: an _AttributeSelection
            if part is None:
                setattr(self, name, values[i])
                i += 1
            else:
                getattr(self, name)[part] = values[i:i + n]
                i += n
        if self._has_feedthrough:
            self._outputs_stale = True

    def setup(self, start_time: float, stop_time: float | None) -> None:
        self.start_time = start_time
        self.stop_time = stop_time

    def enter_initialization(self) -> None:
        self._open_data_files_here()

    def exit_initialization(self) -> None:
        self._open_data_files_here()  # also when a subclass's enter_initialization did not call this one's
        self._call("initialize", self.start_time)
        self._outputs_stale = self._has_feedthrough

    def reset(self) -> None:
        self._call("close", None)
        self._apply_start_values()
        self._outputs_stale = False

    def terminate(self) -> None:
        self._call("close", None)

    def _open_data_files_here(self) -> None:
        """Data-file parameters: the path as the spec wrote it -> the file beside the spec, or its copy on this worker."""
        for name in self.data_files:
            value = getattr(self, name)
            setattr(self, name, self._data_paths.get(value, value))

    # Hooks for subclasses -------------------------------------------------

    def initialize(self) -> None:
        """Called once parameters and start values are set, before stepping."""

    def compute_outputs(self) -> None:
        """Recompute outputs from inputs (units with direct feed-through)."""

    def close(self) -> None:
        """Free resources held by the instance."""

    def get_state(self) -> Any:
        """A snapshot of what the unit keeps besides its variables (a copy, not a reference to live data).

        Defining ``get_state`` and :meth:`set_state` makes the unit's state restorable: a master may then
        take a step back (the adaptive algorithm repeats a rejected step).  cosim saves and restores the
        values of ``variables`` itself; a unit whose whole state is in its variables returns None.
        """
        raise NotImplementedError

    def set_state(self, state: Any) -> None:
        """Return to a snapshot :meth:`get_state` made (it may be restored more than once: copy what you keep)."""
        raise NotImplementedError

    # Saved states (see Unit.save_state): the variables by cosim, the rest by the subclass's hooks

    @property
    def can_save_state(self) -> bool:
        cls = type(self)
        return cls.get_state is not PythonUnit.get_state and cls.set_state is not PythonUnit.set_state

    def save_state(self, reuse: Any = None) -> Any:
        if not self.can_save_state:
            return super().save_state(reuse)
        values = {v.name: _copied(getattr(self, v.name)) for v in self.description.variables}
        try:
            own = self.get_state()
        except Exception as exc:
            raise UnitError.raised(self.name, "get_state", exc, None) from exc
        return values, self._outputs_stale, own

    def restore_state(self, state: Any) -> None:
        if not self.can_save_state:
            return super().restore_state(state)
        values, stale, own = state
        for name, value in values.items():
            setattr(self, name, _copied(value))  # a copy: the snapshot may be restored again
        self._outputs_stale = stale
        try:
            self.set_state(own)
        except Exception as exc:
            raise UnitError.raised(self.name, "set_state", exc, None) from exc

    @property
    def can_serialize_state(self) -> bool:
        return self.can_save_state  # pickled; a state that does not pickle is reported by serialize_state

    def serialize_state(self, state: Any) -> bytes:
        if not self.can_serialize_state:
            return super().serialize_state(state)
        try:
            return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:
            raise UnitError(self.name, f"its saved state (get_state) cannot be pickled: {type(exc).__name__}: {exc}; "
                            "return plain data (numbers, lists, dicts, numpy arrays) from get_state", None) from exc

    def deserialize_state(self, data: bytes) -> Any:
        if not self.can_serialize_state:
            return super().deserialize_state(data)
        try:
            return pickle.loads(data)
        except Exception as exc:
            raise UnitError(self.name, f"a serialized state cannot be read back: {type(exc).__name__}: {exc}",
                            None) from exc

    def _call(self, hook: str, t: float | None) -> None:
        try:
            getattr(self, hook)()
        except (UnitError, SimulationEnded):  # SimulationEnded: the unit ends the run, not an error
            raise
        except Exception as exc:  # a unit's own bug becomes a named unit error
            raise UnitError.raised(self.name, f"{hook}()", exc, t) from exc


class PythonUnitType(UnitType):
    """Blueprint of a Python unit named ``"module:Class"`` or ``"file.py:Class"``.

    Only the target string and base folder are pickled; the class is imported
    where the unit is used, so a Dask worker imports it itself.
    """

    def __init__(self, target: str, base_dir: str | Path | None = None, source_zip: str | None = None):
        self.target = target
        self.base_dir = str(base_dir) if base_dir is not None else None
        self._source_zip: str | None = source_zip  # set on a worker: the module's shipped source
        self._cls: type[PythonUnit] | None = None
        # a data-file parameter's value (as the spec gives it) -> the file it names (cosim.units.python.data_files)
        self.data_paths: dict[str, str] = {}
        self.data_folders: set[str] = set()  # those values of data_paths that name a folder (travel as a zip)

    def __getstate__(self) -> dict[str, Any]:
        return {"target": self.target, "base_dir": self.base_dir, "_source_zip": self._source_zip, "_cls": None,
                "data_paths": self.data_paths, "data_folders": self.data_folders}

    def files(self) -> list[Path]:
        """The unit's ``file.py`` or the source of a module named from the spec's folder (as a zip), then its data files.

        A module beside the spec (``my_units:Gain`` with ``my_units.py`` or the
        package ``my_units/`` in the spec's folder) travels as source, so the
        workers need not have it installed; any other module must be importable
        where units run.  The data files are those of ``data_paths``; a folder
        among them travels as a zip of its content (:func:`cosim.units.python.data_files.pack`).
        """
        return self._source_files() + [pack(p) if value in self.data_folders else Path(p)
                                       for value, p in self.data_paths.items()]

    def _source_files(self) -> list[Path]:
        module, sep, _ = self.target.rpartition(":")
        if not sep:
            return []
        if not module.endswith(".py"):
            source = self._local_source(module)
            return [zip_source(source)] if source is not None else []
        path = Path(module)
        return [path if path.is_absolute() or not self.base_dir else Path(self.base_dir) / path]

    def _local_source(self, module: str) -> Path | None:
        """The file or package folder of ``module``'s top-level name in the spec's folder, if there is one."""
        if not self.base_dir or self._source_zip or _installed(module.split(".")[0], self.base_dir):
            return None
        top = Path(self.base_dir) / module.split(".")[0]
        if top.with_suffix(".py").is_file():
            return top.with_suffix(".py")
        return top if (top / "__init__.py").is_file() else None

    def relocate(self, copies: Sequence[Path]) -> None:
        data = list(copies)[len(copies) - len(self.data_paths):]
        self.data_paths = {value: str(unpack(copy, Path(path).name) if value in self.data_folders else copy)
                           for (value, path), copy in zip(self.data_paths.items(), data)}
        copies = list(copies)[:len(copies) - len(self.data_paths)]
        if not copies:
            return
        module, _, class_name = self.target.rpartition(":")
        if module.endswith(".py"):
            self.target = f"{copies[0]}:{class_name}"
        else:
            self._source_zip = str(copies[0])  # imported from the zip of its source (zipimport)

    def load_class(self) -> type[PythonUnit]:
        """Import and return the class.

        Raises ValueError for a malformed target, ImportError for a module or
        file that cannot be imported (also when importing it exits, crashes or
        takes longer than the import_seconds limit: it is imported in a child
        process first, see :mod:`cosim.units.python.import_guard`) and TypeError when
        the class is not a :class:`PythonUnit`.
        """
        if self._cls is not None:
            return self._cls
        module_name, sep, class_name = self.target.rpartition(":")
        if not sep or not module_name or not class_name:
            raise ValueError(f"'{self.target}' is not of the form 'module:Class' or 'file.py:Class'")
        if module_name.endswith(".py"):
            path = Path(module_name)
            if not path.is_absolute() and self.base_dir:
                path = Path(self.base_dir) / path
            if not path.is_file():
                raise ImportError(f"no such file: {path}")
            key = f"cosim_user_{abs(hash(str(path.resolve())))}"
            module = sys.modules.get(key)
            if module is None:
                import_in_child_first(str(path), self.target, self.base_dir, self._source_zip)
                spec = importlib.util.spec_from_file_location(key, path)
                if spec is None or spec.loader is None:  # not for a .py file: importlib finds a loader for it
                    raise ImportError(f"no Python module loader for {path}")
                module = importlib.util.module_from_spec(spec)
                sys.modules[key] = module
                try:
                    with guarded_import(str(path)):  # sys.exit() or a hang at import: an ImportError
                        spec.loader.exec_module(module)
                except BaseException:
                    sys.modules.pop(key, None)  # a half-run module must not be found next time
                    raise
        else:
            ours = module_name.split(".")[0] in ("cosim", "orchestrator") or _builtin_module(module_name)
            if not ours and module_name not in sys.modules:  # cosim's own units are trusted to import
                import_in_child_first(f"module '{module_name}'", self.target, self.base_dir, self._source_zip)
            with guarded_import(f"module '{module_name}'"):
                module = self._import_module(module_name)
        cls = getattr(module, class_name, None)
        if cls is None:
            raise ImportError(f"module '{module_name}' has no class '{class_name}'")
        if not (isinstance(cls, type) and issubclass(cls, PythonUnit)):
            raise TypeError(f"'{self.target}' is not a subclass of cosim.PythonUnit")
        self._cls = cls
        return cls

    def _import_module(self, module_name: str) -> ModuleType:
        """Import ``module_name``, also looking in its shipped source or the spec's folder (modules beside the spec).

        ``models.NAME`` names a built-in unit: it is imported as ``cosim.models.NAME``, the one name under
        which cosim's built-in units exist in every installation (see ``cosim/__init__.py``), so that a
        source checkout never loads the same class a second time as ``models.NAME``.
        """
        builtin = _builtin_module(module_name)
        if builtin is not None:
            return importlib.import_module(builtin)
        folder = self._source_zip or self.base_dir
        if folder and folder not in sys.path:
            sys.path.insert(0, folder)
            try:
                return importlib.import_module(module_name)
            finally:
                sys.path.remove(folder)
        return importlib.import_module(module_name)

    def describe(self) -> UnitDescription:
        return self.load_class().describe_class()

    def instantiate(self, name: str) -> Unit:
        unit = self.load_class()(name)
        if self.data_paths:
            unit._data_paths = self.data_paths
        return unit


def _copied(value: Any) -> Any:
    """A numpy array copied, any other variable value (an immutable scalar or str) as it is."""
    return value.copy() if isinstance(value, np.ndarray) else value


def zip_source(source: Path) -> Path:
    """A zip of the ``.py`` files of ``source`` (a module file or a package folder), importable by zipimport.

    Written once per content into the temporary folder; the same sources give
    the same bytes (fixed dates, sorted members), so a sweep's payload key and
    resume stay stable.
    """
    import hashlib
    import tempfile
    import zipfile

    files = [source] if source.is_file() else sorted(p for p in source.rglob("*.py") if "__pycache__" not in p.parts)
    root = source.parent
    digest = hashlib.sha256()
    for path in files:
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    target = Path(tempfile.gettempdir()) / "cosim_sources" / f"{source.name.removesuffix('.py')}_{digest.hexdigest()[:16]}.zip"
    if not target.is_file():
        target.parent.mkdir(parents=True, exist_ok=True)
        partial = target.with_suffix(f".{os.getpid()}.part")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
            for path in files:
                info = zipfile.ZipInfo(str(path.relative_to(root)), date_time=(1980, 1, 1, 0, 0, 0))
                archive.writestr(info, path.read_bytes(), zipfile.ZIP_DEFLATED)
        partial.replace(target)
    return target


def _installed(name: str, folder: str) -> bool:
    """Whether ``name`` imports without the spec's folder or the current folder (then workers have it too).

    An installed package (the project's own ``models``, say) is not shipped,
    even when the spec lies beside it: it may read data files next to its code.
    """
    import importlib.machinery

    hidden = {"", os.getcwd(), str(Path(folder).resolve())}
    path = [p for p in sys.path if p not in hidden and str(Path(p).resolve()) not in hidden]
    for finder in sys.meta_path:
        try:
            if finder is importlib.machinery.PathFinder:
                found = importlib.machinery.PathFinder.find_spec(name, path)
            else:
                find = getattr(finder, "find_spec", None)
                found = find(name, None) if find is not None else None
        except Exception:  # a finder that cannot answer does not make the module installed
            found = None
        if found is not None:
            return True
    return False


def _builtin_module(module_name: str) -> str | None:
    """``cosim.models.NAME`` for a spec's ``models.NAME`` when cosim ships that module, else None."""
    if not module_name.startswith("models."):
        return None
    canonical = "cosim." + module_name
    try:
        found = importlib.util.find_spec(canonical)
    except ModuleNotFoundError:  # a parent package of the name does not exist
        return None
    return canonical if found is not None else None


def import_check_child(report_fd: str, token: str, target: str, base_dir: str, source_zip: str) -> None:
    """In the child of :func:`~cosim.units.python.import_guard.import_in_child_first`: import the unit's class,
    then write ``token`` to ``report_fd`` (whatever the import raised)."""
    enter_checking_child()
    unit_type = PythonUnitType(target, base_dir or None, source_zip or None)
    try:
        unit_type.load_class()
    except Exception:  # noqa: BLE001 - an ordinary import error: the parent's own import reports it
        pass
    os.write(int(report_fd), token.encode())
    os._exit(0)  # no exit hooks of the module: they may hang or exit otherwise
