"""Files at the boundary: inputs checked before reading, outputs checked before any work, writes
that are atomic, honour the umask and report a full disk as one line.

    require_input(path, "layout", LayoutError)          # exists, is a file
    lines = text_lines(path, "layout", LayoutError)     # UTF-8 text, else "binary file?"
    require_writable(Path("out/run"), "--out")          # before any work: ConfigError
    require_output(png, "--png", reads=[dataset], suffixes=(".png",))   # every command's outputs
    with atomic_path(path) as tmp: write(tmp)           # tmp replaces path on success only
    with staged([png]) as (tmp_png,): fig.savefig(tmp_png)   # savers that write files beside it
    with writing(path, need_bytes=n): ...               # OSError -> DataError naming path, space

Temporary names start with a dot and end in ``.tmp`` (before any suffix kept), so a killed run
leaves files that `remove_stale` recognises.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import shutil
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

from tactile.errors import ConfigError, DataError

DISK_FULL = (errno.ENOSPC, errno.EDQUOT)
NOT_WRITABLE = (errno.EROFS, errno.EACCES, errno.EPERM)
STAGE_PREFIX = ".handskin-stage-"
# The files a dataset folder (handskin generate, merge, ingest) and a run folder (handskin train)
# consist of: a folder holding one of the first names is one; no other command's output replaces
# any of them. As tactile.dataset.folder, tactile.dataset.manifest, learn.train.checkpoint and
# learn.classical.svm name them (tests/test_bad_inputs.py checks that they agree).
DATASET_MARKS = ("dataset.h5", "manifest.json")
DATASET_FILES = (*DATASET_MARKS, "info.json", "chunks")
RUN_MARKS = ("best.pt", "last.pt", "model.npz")
RUN_FILES = (*RUN_MARKS, "run.toml", "test_metrics.json", "curves.png", "crossval.md")
RUN_FILES += ("finetune.json",)


def require_input(path: Path, what: str, error: type[Exception] = DataError) -> Path:
    """``path`` when it is an existing file; else ``error`` naming ``what`` and the fix."""
    path = Path(path)
    if path.is_dir():
        raise error(f"{path}: a folder, not a {what} file. Fix: give the file's path")
    if not path.is_file():
        raise error(f"{path}: no such {what} file. Fix: check the path")
    return path


def text_lines(path: Path, what: str, error: type[Exception] = DataError) -> list[str]:
    """The lines of a UTF-8 text file; ``error`` naming the file when it is missing or binary."""
    data = require_input(path, what, error).read_bytes()
    try:
        return data.decode("utf-8").splitlines()
    except UnicodeDecodeError as err:
        raise error(
            f"{path}: not a text {what} file (byte 0x{data[err.start]:02x} at offset "
            f"{err.start} is not UTF-8; a binary file?). Fix: give the {what} as text"
        ) from None


def count_lines(path: Path) -> int:
    """Lines in a file, counted in bytes without decoding (fast on large files)."""
    with open(path, "rb") as fh:
        return sum(block.count(b"\n") for block in iter(lambda: fh.read(1 << 20), b""))


def nearest_existing(path: Path) -> Path:
    """``path`` or its closest existing ancestor."""
    path = Path(os.path.abspath(path))
    return next(p for p in (path, *path.parents) if p.exists())


def require_writable(path: Path, flag: str, folder: bool = False) -> None:
    """ConfigError, before any work, when ``path`` (a file, or a folder if ``folder``) cannot be
    written: under a file, a folder where a file is wanted, on a read-only disk, no permission."""
    path = Path(path)
    base = nearest_existing(path)
    if base.is_file() and (folder or base != Path(os.path.abspath(path))):
        raise ConfigError(f"{flag} {path}: {base} is a file, not a folder. Fix: another path")
    if not folder and base == Path(os.path.abspath(path)) and base.is_dir():
        raise ConfigError(f"{flag} {path} is a folder. Fix: give a file name, e.g. {path}/x.png")
    where = base if base.is_dir() else base.parent
    if _read_only(where):
        raise ConfigError(f"{flag} {path}: {where} is on a read-only disk. Fix: {_fix(flag)}")
    if not os.access(where, os.W_OK | os.X_OK) or (base.is_file() and not os.access(base, os.W_OK)):
        raise ConfigError(f"{flag} {path}: no permission to write in {where}. Fix: {_fix(flag)}")


def require_output(
    path: Path | None,
    flag: str,
    *,
    reads: Iterable[Path | None] = (),
    suffixes: Sequence[str] = (),
    derived: Iterable[Path] = (),
    folder: bool = False,
    makes: str = "",
) -> None:
    """ConfigError, before any work, for an output ``path`` given as ``flag`` (None: not given).

    Refused: a path `require_writable` refuses; a file (``path`` or a ``derived`` file written
    beside it) that is, once symlinks and ``..`` are resolved, a file the command ``reads`` or
    lies in a folder it reads, or one of the files a dataset or run folder consists of
    (``DATASET_FILES``, ``RUN_FILES``); a file whose suffix is not among ``suffixes`` (given:
    what will be written). A ``folder`` output may not be a folder the command reads, nor a
    dataset or run folder unless it ``makes`` one of that kind ("dataset" or "run"); the files
    it will hold, ``derived``, are checked as files.
    """
    if path is None:
        return
    path = Path(path)
    require_writable(path, flag, folder)
    inputs = {Path(os.path.realpath(p)): Path(p) for p in reads if p is not None}
    if folder:
        _own_folder(path, flag, inputs, makes)
    for target in [*derived] if folder else [path, *derived]:
        _not_an_input(Path(target), path, flag, inputs)
    if not folder and suffixes and path.suffix.lower() not in suffixes:
        raise ConfigError(
            f"{flag} {path}: name the file with a {' or '.join(suffixes)} suffix, as what is "
            f"written there. Fix: e.g. {flag} {path.with_suffix(suffixes[0])}"
        )


def _not_an_input(target: Path, path: Path, flag: str, inputs: dict[Path, Path]) -> None:
    """ConfigError when writing ``target`` (for ``flag path``) would replace an input (``inputs``:
    resolved path -> as given) or a file of a dataset or run folder."""
    real = Path(os.path.realpath(target))
    if not real.exists():
        return
    head = f"{flag} {path} would" + ("" if target == path else f" also write {target} and")
    link = [] if Path(os.path.abspath(target)) == real else [f"{target} links to {real}"]
    for p, given in inputs.items():
        if real == p or p in real.parents or (p.exists() and os.path.samefile(real, p)):
            where = "; ".join(link + ([] if real == p else [f"in {given}"]))
            raise ConfigError(
                f"{head} write over a file this command reads{f' ({where})' if where else ''}. "
                f"Fix: give another {flag} path"
            )
    kind, home = folder_kind(real.parent)
    if kind is None and real.parent.name == "chunks":
        kind, home = folder_kind(real.parent.parent)
    members = DATASET_FILES if kind == "dataset" else RUN_FILES
    if kind is not None and real.relative_to(home).parts[0] in members:
        raise ConfigError(
            f"{head} replace {real.relative_to(home)} of the {kind} folder {_near(home)}. "
            f"Fix: give another {flag} path (outside that folder, or another file name)"
        )


def _own_folder(path: Path, flag: str, inputs: dict[Path, Path], makes: str) -> None:
    """ConfigError when an output folder is one the command reads, or a dataset or run folder
    (or its chunks/) of another kind than the command ``makes``."""
    real = Path(os.path.realpath(path))
    if real in inputs:
        raise ConfigError(
            f"{flag} {path} is the folder this command reads. Fix: give a new {flag} folder"
        )
    kind, home = folder_kind(real)
    if kind is None and real.name == "chunks":
        kind, home = folder_kind(real.parent)
    if kind is not None and kind != makes:
        raise ConfigError(
            f"{flag} {path}: {_near(home)} is a {kind} folder; this command would mix its "
            f"files with the {kind}'s. Fix: give a new {flag} folder"
        )


def _near(path: Path) -> Path:
    """``path`` relative to the working folder when it lies inside it."""
    try:
        return path.relative_to(Path.cwd())
    except ValueError:
        return path


def folder_kind(folder: Path) -> tuple[str | None, Path]:
    """("dataset" or "run" or None, ``folder``): whether ``folder`` holds a dataset (a
    ``DATASET_MARKS`` file) or a training run (a ``RUN_MARKS`` file)."""
    folder = Path(folder)
    if any((folder / name).exists() for name in DATASET_MARKS):
        return "dataset", folder
    if any((folder / name).is_file() for name in RUN_MARKS):
        return "run", folder
    return None, folder


def _read_only(folder: Path) -> bool:
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _fix(flag: str) -> str:
    return f"give an {flag} path you may write to" if flag else "write somewhere you may"


def free_bytes(path: Path) -> int | None:
    """Free bytes on the disk holding ``path`` (or its closest existing ancestor)."""
    try:
        return shutil.disk_usage(nearest_existing(path)).free
    except OSError:
        return None


def size_text(n: float) -> str:
    """Bytes as ``812 kB`` / ``3.4 MB`` / ``1.2 GB``."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} bytes"


def is_disk_full(err: BaseException) -> bool:
    """True for an OSError (or HDF5's RuntimeError text) saying the disk or quota is full."""
    if isinstance(err, OSError) and err.errno in DISK_FULL:
        return True
    return "errno = 28" in str(err) or "No space left on device" in str(err)


def disk_error(
    err: BaseException, path: Path, need_bytes: float | None = None, fix: str = ""
) -> DataError:
    """A one-line DataError for a failed write of ``path`` (or the file the error names): full
    disk (with the free space and, when known, ``need_bytes``), read-only disk or permission,
    else the system's words."""
    path = Path(err.filename) if isinstance(err, OSError) and err.filename else Path(path)
    if is_disk_full(err):
        free = free_bytes(path)
        have = f"{size_text(free)} free there" if free is not None else "no space left"
        need = f"; about {size_text(need_bytes)} needed" if need_bytes else ""
        why = f"the disk is full ({have}{need})"
        fix = fix or "free space on that disk, or write somewhere else"
    elif isinstance(err, OSError) and err.errno in NOT_WRITABLE:
        why = "read-only disk" if err.errno == errno.EROFS else "permission denied"
        fix = fix or "write somewhere you may"
    else:
        why = getattr(err, "strerror", None) or str(err).splitlines()[0]
        fix = fix or "check that disk"
    return DataError(f"cannot write {path}: {why}. Fix: {fix}")


def os_error_text(err: OSError) -> str:
    """One line for an OSError no caller caught: the file, what happened, the fix."""
    if err.filename:
        return str(disk_error(err, Path(err.filename)))
    if is_disk_full(err):
        return "the disk is full. Fix: free space on the output's disk, or write somewhere else"
    text = str(err).splitlines()[0]
    if "read data" in text:
        return f"a file could not be read ({text}). Fix: check it with handskin verify DATASET"
    return text


@contextlib.contextmanager
def writing(path: Path, need_bytes: float | None = None, fix: str = "") -> Iterator[None]:
    """Turn an OSError raised while writing ``path`` into `disk_error`'s one line."""
    try:
        yield
    except OSError as err:
        raise disk_error(err, Path(path), need_bytes, fix) from err


def _temp_name(path: Path, keep_suffix: bool) -> Path:
    suffix = path.suffix if keep_suffix else ""
    return path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp{suffix}")


@contextlib.contextmanager
def atomic_path(path: Path, keep_suffix: bool = False) -> Iterator[Path]:
    """Yield a new, empty temporary file in ``path``'s folder; on success it replaces ``path``
    atomically, on any exception it is removed and ``path`` is left as it was. The file is
    created with mode 0666 less the umask, as ``open`` creates files."""
    path = Path(path)
    tmp = _temp_name(path, keep_suffix)
    os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.errno and err.filename in (None, str(tmp)):
            raise OSError(err.errno, err.strerror or str(err), str(path)) from err  # names path
        raise


def write_text_atomic(path: Path, text: str) -> None:
    """Write UTF-8 text atomically (`atomic_path`)."""
    with atomic_path(Path(path)) as tmp:
        tmp.write_text(text, encoding="utf-8")


def save_figure(fig, path: str | os.PathLike[str], dpi: float = 100, **kw) -> Path:
    """Write a matplotlib figure to ``path`` atomically, creating the folder; the format comes
    from the suffix (PNG when there is none). Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=path.suffix[1:].lower() or "png", **kw)
    return path


def save_image(image, path: str | os.PathLike[str], **kw) -> Path:
    """Write a PIL image to ``path`` atomically (format from the suffix, PNG when none)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fmt = {".jpg": "JPEG", ".jpeg": "JPEG", ".gif": "GIF", ".bmp": "BMP"}
    with atomic_path(path) as tmp:
        image.save(tmp, format=fmt.get(path.suffix.lower(), "PNG"), **kw)
    return path


@contextlib.contextmanager
def staged(paths: Sequence[Path | None]) -> Iterator[list[Path | None]]:
    """Yield, for each output path (None passes through), the same file name in a hidden folder
    beside it; on success every file written into those folders moves next to its path (so a
    saver's extra files, e.g. ``<stem>_parts.png``, move too), on failure none does."""
    stages: dict[Path, Path] = {}
    out: list[Path | None] = []
    try:
        for p in paths:
            if p is None:
                out.append(None)
                continue
            parent = Path(p).parent
            if parent not in stages:
                parent.mkdir(parents=True, exist_ok=True)
                stages[parent] = parent / f"{STAGE_PREFIX}{secrets.token_hex(4)}"
                stages[parent].mkdir()
            out.append(stages[parent] / Path(p).name)
        yield out
        for parent, stage in stages.items():
            for f in sorted(stage.iterdir()):
                os.replace(f, parent / f.name)
    finally:
        for stage in stages.values():
            shutil.rmtree(stage, ignore_errors=True)


def final_path(staged_path: Path) -> Path:
    """Where a file written at a `staged` path ends up."""
    return staged_path.parent.parent / staged_path.name


def remove_stale(folder: Path, pattern: str = ".*.tmp*") -> list[Path]:
    """Delete the temporary files (`atomic_path`) and stage folders a killed run left in
    ``folder``; returns what was removed."""
    gone = []
    if Path(folder).is_dir():
        for p in sorted(Path(folder).glob(pattern)) + sorted(Path(folder).glob(STAGE_PREFIX + "*")):
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
            gone.append(p)
    return gone
