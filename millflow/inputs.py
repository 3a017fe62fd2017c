"""Reading the user's files: one place for encodings, TOML syntax and CSV parsing errors.

Every reader returns the parsed content or raises :class:`~millflow.errors.InputError`
with one line naming the file and what is wrong:

- text is UTF-8, with or without a byte-order mark; anything else (Latin-1, UTF-16,
  binary) names the byte offset of the first byte that is not UTF-8 and says to save
  the file as UTF-8;
- TOML syntax errors keep tomllib's line and column;
- CSV files are read by pandas from the decoded text, so the same rules hold, and
  parser errors name the file.
"""
from __future__ import annotations

import codecs
import io
import json
import tomllib
from pathlib import Path

from millflow.errors import InputError

__all__ = ["read_text", "read_toml", "read_json", "read_csv"]


def read_text(path, what: str = "file") -> str:
    """The file's text, decoded as UTF-8 (a leading byte-order mark is dropped)."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{p}: {what} not found") from None
    except IsADirectoryError:
        raise InputError(f"{p}: is a folder; expected a {what}") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read the {what}: {exc.strerror or exc}") from None
    if raw.startswith(codecs.BOM_UTF16_LE) or raw.startswith(codecs.BOM_UTF16_BE):
        raise InputError(f"{p}: the {what} is UTF-16 encoded; save it as UTF-8")
    nul = raw.find(b"\x00", 0, 4096)
    if nul >= 0:
        raise InputError(f"{p}: the {what} is binary (a NUL byte at offset {nul}); expected UTF-8 text")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise InputError(f"{p}: byte {exc.start} (line {line}) is not UTF-8 (0x{raw[exc.start]:02x}); "
                         f"save the {what} as UTF-8") from None


def read_toml(path, what: str = "TOML file") -> dict:
    """The parsed TOML file (syntax errors name the file, line and column)."""
    text = read_text(path, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{Path(path)}: not valid TOML ({exc})") from None


def read_json(path, what: str = "JSON file"):
    """The parsed JSON file (syntax errors name the file, line and column)."""
    text = read_text(path, what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{Path(path)}: not valid JSON ({exc.msg} at line {exc.lineno}, "
                         f"column {exc.colno})") from None


def read_csv(path, what: str = "CSV file", **kw):
    """A pandas DataFrame of the CSV file (encoding and parser errors name the file)."""
    import pandas as pd

    text = read_text(path, what)
    try:
        return pd.read_csv(io.StringIO(text), **kw)
    except pd.errors.EmptyDataError:
        raise InputError(f"{Path(path)}: the {what} is empty") from None
    except (pd.errors.ParserError, ValueError) as exc:
        msg = " ".join(str(exc).split())
        raise InputError(f"{Path(path)}: cannot read the {what}: {msg}") from None
