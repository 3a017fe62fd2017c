"""Result folders written whole or not at all, and never over files the user made.

Every command that writes files does it through :func:`staged_folder`:

1. Before any work, :func:`check_target` refuses a target that cannot be written (a file
   where a folder is expected, a missing parent folder, a read-only parent) and a folder
   that holds files millflow did not write (no manifest, or files the manifest does not
   list, or a manifest written for another input file) unless ``--overwrite`` is given.
2. The files are written into a temporary folder beside the target.
3. Only when every file is complete is a manifest (:data:`MANIFEST`: files, millflow
   version, input file and its SHA-256, command, time) added and the temporary folder
   renamed into place; an earlier millflow folder is moved aside first and removed
   after. On any failure, SIGINT or SIGTERM the temporary folder is removed and the
   target is left as it was.

OS errors (full disk, permissions) become :class:`~millflow.errors.OutputError`
(exit status 1 on the command line); a refused target is an
:class:`~millflow.errors.InputError` (exit status 2).
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path

from millflow.errors import InputError, OutputError

#: Name of the manifest millflow writes into every result folder.
MANIFEST = ".millflow-manifest.json"


def file_sha256(path) -> str | None:
    """SHA-256 of a file's bytes (None if it cannot be read)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def read_manifest(folder: Path) -> dict | None:
    """The folder's manifest, or None if it has none (or an unreadable one)."""
    try:
        data = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("files"), list) else None


def foreign_files(folder: Path) -> list[str]:
    """Files in ``folder`` that millflow's manifest there does not list (all of them
    when there is no manifest), relative to the folder, sorted."""
    manifest = read_manifest(folder)
    known = set(manifest["files"]) if manifest else set()
    known.add(MANIFEST)
    found = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir())
    return [f for f in found if f not in known]


def check_target(out: Path, *, overwrite: bool = False, input_path=None, flag: str = "--out") -> None:
    """Refuse, before any work is done, a result folder that cannot or may not be written."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{flag} {out}: is a file; expected a folder")
    parent = out.resolve().parent
    if not parent.is_dir():
        raise OutputError(f"{flag} {out}: the parent folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{flag} {out}: the parent folder {parent} is not writable")
    if not out.is_dir() or overwrite:
        return
    foreign = foreign_files(out)
    if foreign:
        shown = ", ".join(foreign[:4]) + (f" and {len(foreign) - 4} more" if len(foreign) > 4 else "")
        raise InputError(f"{flag} {out}: holds files millflow did not write ({shown}); "
                         "choose another folder or give --overwrite to replace it")
    manifest = read_manifest(out)
    if manifest and input_path is not None and manifest.get("input"):
        mine = str(Path(input_path).resolve())
        if manifest["input"] != mine:
            raise InputError(f"{flag} {out}: holds millflow results of another input ({manifest['input']}); "
                             "choose another folder or give --overwrite to replace them")


@contextlib.contextmanager
def staged_folder(out, *, overwrite: bool = False, input_path=None, command: str = "", flag: str = "--out"):
    """Yield a temporary folder beside ``out``; move it into place when the block ends
    without an error (see the module docstring)."""
    out = Path(out)
    check_target(out, overwrite=overwrite, input_path=input_path, flag=flag)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.millflow-", dir=out.resolve().parent))
    except OSError as exc:
        raise OutputError(f"{flag} {out}: cannot create a folder beside it: {exc.strerror or exc}") from None
    try:
        yield tmp
        files = sorted(p.relative_to(tmp).as_posix() for p in tmp.rglob("*") if not p.is_dir())
        from millflow import __version__

        manifest = {"files": files, "millflow_version": __version__, "command": command,
                    "input": None if input_path is None else str(Path(input_path).resolve()),
                    "input_sha256": None if input_path is None else file_sha256(input_path),
                    "written": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
        _replace(tmp, out)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, OutputError):
            raise
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        raise OutputError(f"{flag} {out}: results not written: {exc.strerror or exc}{where}; "
                          "the folder is as it was") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _replace(tmp: Path, out: Path) -> None:
    """Rename ``tmp`` to ``out``; an existing ``out`` is moved aside first and removed
    after, and put back if the rename fails."""
    if not out.exists():
        tmp.rename(out)
        return
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}.millflow-old-", dir=out.resolve().parent))
    old.rmdir()
    out.rename(old)
    try:
        tmp.rename(out)
    except BaseException:
        old.rename(out)
        raise
    shutil.rmtree(old, ignore_errors=True)


def relocate(paths, tmp: Path, out: Path) -> list[str]:
    """Paths written under ``tmp`` as they are named once moved to ``out``."""
    return [str(Path(out) / Path(p).relative_to(tmp)) for p in paths]


#: The one meaning of ``--quiet`` in every command (docs/cli.md).
QUIET_HELP = "no progress bars or progress messages on stderr (the results still print)"


def add_output_flags(p, *, out: str, json: str, plots: str, quiet: str | None = None) -> None:
    """The output flags every writing command shares, one meaning each: ``--out DIR`` (a
    folder), ``--json``, ``--no-plots``, ``--quiet`` (:data:`QUIET_HELP`: progress only),
    ``--overwrite``; the help texts say what the others mean for that command (``quiet``
    is accepted and ignored: the flag has one meaning)."""
    p.add_argument("--out", default=None, help=out)
    p.add_argument("--json", action="store_true", help=json)
    p.add_argument("--no-plots", action="store_true", help=plots)
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.add_argument("--overwrite", action="store_true",
                   help="replace an output folder that holds files millflow did not write")



def write_extras(sol, summary: dict, folder, *, input_path=None, command: str = "millflow run") -> dict:
    """``report.html`` (always) and ``results.xlsx`` (when openpyxl is installed) of a
    solved flowsheet into ``folder``; returns name -> path."""
    from millflow.report import partition_curves, write_report

    folder = Path(folder)
    files = {"report_html": write_report(folder / "report.html", summary, input_path=input_path,
                                         partition=partition_curves(sol), command=command)}
    from millflow.report.excel import excel_available, write_workbook

    if excel_available():
        from millflow.report.excel import class_flows_tph

        files["results_xlsx"] = write_workbook(folder / "results.xlsx", summary, class_flows_tph(sol))
    else:
        excel_missing_note()
    return files


#: The one note when results.xlsx cannot be written (docs/cli.md).
EXCEL_NOTE = "results.xlsx not written: pip install 'millflow[report]'"


def excel_missing_note() -> None:
    """Say on stderr, once per command, that results.xlsx was not written and how to get it."""
    import sys

    print(f"millflow: note: {EXCEL_NOTE}", file=sys.stderr)


def deprecated_alias(p, old: str, new: str, dest: str) -> None:
    """``old`` as a hidden alias of the option ``new`` (same ``dest``), warning when used."""
    import argparse
    import sys

    class _Alias(argparse.Action):
        def __call__(self, parser, namespace, values, option_string=None):
            # printed, not warnings.warn: arguments are parsed before main() formats warnings
            print(f"{parser.prog}: warning: {old} is deprecated here; use {new}", file=sys.stderr)
            setattr(namespace, dest, values)

    p.add_argument(old, dest=dest, action=_Alias, help=argparse.SUPPRESS)
