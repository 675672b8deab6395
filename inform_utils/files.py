"""The files the tools of inform_utils/ read and write, checked and atomic: a file that is missing, a dangling link,
unreadable, half-written or damaged is one line (BadFile, a ValueError, so a tool's `error:` line and exit 2), and a
file a tool writes appears whole or not at all (written beside its place, then os.replace)."""

import contextlib
import hashlib
import json
import os
import shutil
import tempfile
import zipfile

import numpy as np


class BadFile(ValueError):
    """A file a tool reads is missing, unreadable, half-written or damaged: one line that names it and says why."""


def why_unreadable(path: str, e: Exception) -> str:
    """What keeps `path` from being read, in a few words."""
    if isinstance(e, FileNotFoundError):
        return "a dangling link" if os.path.islink(path) else "no such file"
    if isinstance(e, IsADirectoryError):
        return "a directory, not a file"
    if isinstance(e, PermissionError):
        return "permission denied"
    if isinstance(e, OSError):
        return e.strerror or type(e).__name__
    return f"half-written or damaged ({type(e).__name__}: {str(e)[:120]})"


def read_json(path: str) -> dict:
    """A JSON object from `path`; BadFile, one line, for anything else."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, ValueError) as e:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise BadFile(f"{path}: cannot read it ({why_unreadable(path, e)})") from None
    if not isinstance(data, dict):
        raise BadFile(f"{path}: not a JSON object (damaged, or not the file it should be)")
    return data


def read_npz(path: str, keys: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Every array of an .npz, read whole (each member's CRC-32 is checked as it is read; nothing is unpickled);
    BadFile, one line, for a file that is missing, truncated or damaged, or that lacks one of `keys`."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except Exception as e:  # a damaged archive fails in many ways (BadZipFile, EOFError, zlib.error, ValueError)
        raise BadFile(f"{path}: cannot read it ({why_unreadable(path, e)})") from None
    missing = [k for k in keys if k not in arrays]
    if missing:
        raise BadFile(f"{path}: no {', '.join(missing)} array (holds {', '.join(arrays) or 'none'})")
    return arrays


def check_crc(path: str) -> None:
    """torch.save writes a zip archive with a CRC-32 per member, which torch.load never checks: BadFile, one line, for
    an archive that is missing, truncated or whose bytes changed since it was saved (the scripts' own check_crc)."""
    try:
        with zipfile.ZipFile(path) as archive:
            damaged = archive.testzip()
    except Exception as e:  # BadZipFile, EOFError, OSError, a garbled name
        raise BadFile(f"{path}: not a complete torch checkpoint ({why_unreadable(path, e)})") from None
    if damaged is not None:
        raise BadFile(f"{path}: damaged since it was saved ({damaged} fails its CRC-32 check); make it again")


def sha256(path: str) -> str:
    """The file's content as a hex digest (what names a saved day, whatever its folder is called)."""
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
    except OSError as e:
        raise BadFile(f"{path}: cannot read it ({why_unreadable(path, e)})") from None
    return digest.hexdigest()


@contextlib.contextmanager
def atomic(path: str, mode: str = "w"):
    """Open a temporary file beside `path` for writing; on success it replaces `path` whole, on any error it is
    removed and `path` is as it was."""
    folder, name = os.path.split(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, mode) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_json(path: str, data, indent: int = 1) -> None:
    with atomic(path) as f:
        json.dump(data, f, indent=indent)


def copy(src: str, dest: str) -> None:
    """Copy a file's bytes to `dest` (a file path), whole or not at all."""
    with open(src, "rb") as f, atomic(dest, "wb") as out:
        shutil.copyfileobj(f, out)


def check_writable(folder: str, flag: str) -> None:
    """Before any work: `folder` (made later if it does not exist) can receive files. Tries a temporary file in it,
    or in its nearest existing parent, and leaves nothing behind; ValueError, one line, if it cannot."""
    probe = os.path.abspath(folder)
    while not os.path.lexists(probe):
        probe = os.path.dirname(probe)
    if not os.path.isdir(probe):
        what = "a dangling link" if os.path.islink(probe) else "a file"
        raise ValueError(f"{flag} {folder}: {probe} is {what}, not a directory")
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as e:
        raise ValueError(f"{flag} {folder}: cannot write into {probe} ({why_unreadable(probe, e)})") from None
