"""The files the tools of inform_utils/ read and write, checked and atomic: a file that is missing, a dangling link,
unreadable, half-written or damaged is one line (BadFile, a ValueError, so a tool's `error:` line and exit 2), and a
file a tool writes appears whole or not at all (written beside its place, then os.replace). And how a tool ends
(run_tool): bad input in one `error:` line with exit 2, a stop signal between two steps in one line with exit 128 +
the signal, never half-way through a write."""

import contextlib
import hashlib
import json
import os
import secrets
import shutil
import signal
import sys
import tempfile
import zipfile

import numpy as np


class BadInput(ValueError):
    """Bad input to a tool (a flag's value, a file): one line that says what is wrong and how to put it right, raised
    before any work; run_tool prints it as `error: ...` and exits 2."""


class BadFile(BadInput):
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
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):  # np.load reads an .npy (whatever its name) as one array
            raise BadFile(f"{path}: one .npy array, not an .npz archive of named arrays")
        with loaded as data:
            arrays = {name: data[name] for name in data.files}
    except BadFile:
        raise
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
    removed and `path` is as it was. The file gets the mode open() gives a new one (the umask's: mkstemp's 0600 would
    hide a teacher's demonstrations or a check's JSON from the group)."""
    folder, name = os.path.split(os.path.abspath(path))
    while True:
        tmp = os.path.join(folder, f".{name}.{secrets.token_hex(6)}.tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:  # 48 random bits: a leftover of the same name, at most
            continue
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
    or in its nearest existing parent, and leaves nothing behind; BadInput, one line, if it cannot."""
    probe = os.path.abspath(folder)
    while not os.path.lexists(probe):
        probe = os.path.dirname(probe)
    if not os.path.isdir(probe):
        what = "a dangling link" if os.path.islink(probe) else "a file"
        raise BadInput(f"{flag} {folder}: {probe} is {what}, not a directory")
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as e:
        raise BadInput(f"{flag} {folder}: cannot write into {probe} ({why_unreadable(probe, e)})") from None


def cut(text, limit: int = 200) -> str:
    """`text` on one line, whole if it fits in `limit` characters; else the whole words (names, quoted keys) that fit
    and how long it was: a value echoed in an error line is never 5,000 characters, nor a name cut in two."""
    text = " ".join(str(text).split())
    if len(text) <= limit:
        return text
    head = text[:limit]
    if text[limit] != " " and " " in head[limit // 2 :]:  # drop the word the limit cuts; one long word is cut
        head = head[: head.rindex(" ")]
    return f"{head.rstrip(' ,;:')} ... ({len(text):,} characters)"


# ---------------------------------------------------------------------------------------------------------------------
# how a tool ends: run_tool


class Stopped(Exception):
    """A stop signal came: raised by Stop.check() at a step of the tool's own loop, never inside a library's call or a
    write (a tool that stops so writes its files at the end only)."""


class Stop:
    """The first stop signal (SIGINT, SIGTERM, SIGHUP) a tool run by run_tool(..., stops=True) received. The handler
    only records it; the tool calls Stop.check() between its steps."""

    signum: int | None = None

    @staticmethod
    def record(signum, frame) -> None:
        Stop.signum = Stop.signum or signum

    @classmethod
    def check(cls) -> None:
        if cls.signum is not None:
            raise Stopped


class Interrupted(BaseException):
    """SIGTERM or SIGHUP in a tool without `stops`, raised where it is as Ctrl-C's KeyboardInterrupt is, so that the
    tool's `finally` and `except BaseException` end what it started (a day's run in its own session, a browser)."""


def interrupt(signum, frame) -> None:
    for sig in (signal.SIGTERM, signal.SIGHUP):  # a second one must not cut short the cleanup the first one started
        signal.signal(sig, signal.SIG_IGN)
    raise Interrupted(signum)


def run_tool(main, *args, stops: bool = False):
    """A tool's command line: main(*args), whose return value, if an int, is the exit code (else 0). BadInput (BadFile
    too) is one line `error: ...` on stderr and exit 2. With `stops` a stop signal is recorded and main stops at its
    next Stop.check(): one line, exit 128 + the signal (130 SIGINT, 143 SIGTERM); one that comes after main's last
    check (during its save) lets the save finish whole, then the same exit. Without `stops`, Ctrl-C, SIGTERM and
    SIGHUP are raised where main is (its writes are whole or not made): one line and exit 128 + the signal too."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is signal.SIG_IGN:  # nohup, `&`: an ignored signal stays ignored
            continue
        if stops:
            signal.signal(sig, Stop.record)
        elif sig != signal.SIGINT:  # Python raises KeyboardInterrupt for SIGINT itself
            signal.signal(sig, interrupt)
    try:
        code = main(*args)
    except BadInput as e:
        print(f"error: {cut(e, 2000)}", file=sys.stderr)
        sys.exit(2)
    except Stopped:
        print(f"interrupted ({signal.Signals(Stop.signum).name}) before the work was done; nothing was written",
              file=sys.stderr)  # fmt: skip
        sys.exit(128 + Stop.signum)
    except (KeyboardInterrupt, Interrupted) as e:
        signum = e.args[0] if isinstance(e, Interrupted) else signal.SIGINT
        print(f"interrupted ({signal.Signals(signum).name}) before the work was done", file=sys.stderr)
        sys.exit(128 + signum)
    if Stop.signum is not None:
        print(f"{signal.Signals(Stop.signum).name} received at the end; what was written is whole", file=sys.stderr)
        sys.exit(128 + Stop.signum)
    sys.exit(code if isinstance(code, int) else 0)
