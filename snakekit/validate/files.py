"""Checks of files the kit reads and writes: a path of the right type, a file that exists and
is a regular file, a folder that takes a new file, an ``.npz`` archive that is whole and not
too large. Their errors name the path (a short excerpt of a long one) and what to do.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import ConfigurationError, FileFormatError, FileWriteError, InputTypeError
from . import MAX_POINTS, excerpt, quote


def as_path(path, what: str) -> Path:
    """``path`` (a ``str`` or ``os.PathLike``) as a Path, or an error naming what a path is.

    Raises:
        InputTypeError: ``path`` is not a str or path (a number, None, a list...).
        ConfigurationError: it holds a NUL character, which no file name can.
    """
    if not isinstance(path, (str, os.PathLike)) or isinstance(path, bytes):
        raise InputTypeError(f"the {what} must be a path (a str or pathlib.Path), got {quote(path)} "
                             f"({type(path).__name__}); e.g. 'run.npz'")
    path = Path(path)
    if "\0" in str(path):
        raise ConfigurationError(f"the {what} {quote(str(path))} holds a NUL character, which no file name can "
                                 "hold; give a file name without it")
    return path


def writable_file(path, what: str, *, probe: bool = True) -> Path:
    """``path`` as a Path, if ``what`` (e.g. "run file") can be written there.

    With ``probe``, a file is really opened there for writing (and removed again if it was
    not there before): permission bits do not tell everything (read-only mounts, /proc...),
    so this is how a long job checks its output before it starts.

    Raises:
        FileWriteError: the folder is missing, the path is a folder, or writing fails; the
            message says which and what to do.
    """
    path = as_path(path, what)
    parent = path.absolute().parent
    try:
        parent_is_dir, parent_exists, is_dir = parent.is_dir(), parent.exists(), path.is_dir()
    except OSError as e:  # a name longer than the system allows...
        raise write_failed(path, what, e) from None
    if not parent_is_dir:
        state = "is a file, not a folder" if parent_exists else "does not exist"
        raise FileWriteError(f"cannot write {what} {path}: folder {parent} {state}. Create the folder first "
                             f"(pathlib.Path('{parent}').mkdir(parents=True)) or choose another path")
    if is_dir:
        raise FileWriteError(f"cannot write {what} {path}: it is a folder. Give a file name inside it, "
                             f"e.g. {path / ('name' + path.suffix)}")
    if probe:
        existed = path.exists()
        try:
            with open(path, "ab"):
                pass
            if not existed:
                path.unlink()
        except OSError as e:
            raise write_failed(path, what, e) from e
    return path


def write_failed(path, what: str, e: OSError) -> FileWriteError:
    """The error for an ``OSError`` while writing ``what`` to ``path``."""
    return FileWriteError(f"cannot write {what} {excerpt(path)}: {e.strerror or e}. Choose a place you can write to "
                          "(e.g. a file in your home folder)")


def readable_file(path, what: str) -> Path:
    """``path`` as a Path, if it is an existing regular file (not a folder, pipe or device).

    Raises:
        FileFormatError: it does not exist, it is a folder, or it is not a regular file (a
            named pipe would make reading wait forever).
    """
    path = as_path(path, what)
    try:
        is_dir, exists, is_file = path.is_dir(), path.exists(), path.is_file()
    except OSError as e:  # a name longer than the system allows...
        raise FileFormatError(f"{what} {excerpt(path)} can't be opened: {e.strerror or e}; give the path of a "
                              "file saved on disk") from None
    if is_dir:
        raise FileFormatError(f"{what} {path} is a folder, not a file; give the path of the "
                              "file itself")
    if not exists:
        raise FileFormatError(f"{what} {path} does not exist")
    if not is_file:  # a pipe or a device: reading it could wait forever
        raise FileFormatError(f"{what} {path} is not a regular file (a pipe, socket or device); give the "
                              "path of a file saved on disk")
    return path


def _stored_shape(z, name: str) -> tuple | None:
    """The shape of array ``name`` in the open .npz ``z``, read from its header only (None if
    the header is of a version this does not read: the array is then checked once loaded)."""
    member = name + ".npy" if name + ".npy" in z.zip.namelist() else name
    with z.zip.open(member) as f:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            return np.lib.format.read_array_header_1_0(f)[0]
        if version == (2, 0):
            return np.lib.format.read_array_header_2_0(f)[0]
    return None


def read_npz(path, what: str, required: tuple, optional: tuple = (), *, fix: str) -> dict:
    """The arrays ``required`` (and those of ``optional`` it holds) of the ``.npz`` file at ``path``.

    Each array's size is read from its header before the array itself: a file that claims a
    billion points is refused without the memory being taken.

    Args:
        what: what the file is, for messages ("run file").
        fix: what to do about a damaged file ("save runs with Run.save").

    Raises:
        FileFormatError: missing, a folder, truncated, damaged (a bad checksum), not an .npz
            archive, lacking an array, or holding one larger than :data:`MAX_POINTS` rows.
    """
    import tokenize
    import zipfile
    import zlib

    path = readable_file(path, what)
    if path.stat().st_size == 0:
        raise FileFormatError(f"{path} is empty, not a {what}; {fix}")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise FileFormatError(f"{path} holds a single array (a .npy file), not the .npz archive of a {what}; "
                                  f"{fix}")
        with loaded as z:
            missing = [k for k in required if k not in z.files]
            if missing:
                raise FileFormatError(f"{path} is not a snakekit {what}: it lacks the array(s) {missing}. "
                                      f"{fix[:1].upper()}{fix[1:]}")
            out = {}
            for k in (*required, *(k for k in optional if k in z.files)):
                shape = _stored_shape(z, k)
                if shape is not None and ((shape[0] if shape else 1) > MAX_POINTS
                                          or int(np.prod(shape)) > 100 * MAX_POINTS):
                    raise FileFormatError(f"{path}: array '{k}' has shape {shape}, more than the {MAX_POINTS} points "
                                          f"the kit handles; it was not read")
                out[k] = z[k]
            return out
    except FileFormatError:
        raise
    except (OSError, ValueError, EOFError, KeyError, RuntimeError, SyntaxError, tokenize.TokenError,
            zipfile.BadZipFile, zlib.error) as e:  # a damaged archive (a flipped flag reads "encrypted": RuntimeError),
        # or a damaged array header (numpy parses it as Python: SyntaxError, TokenError, NotImplementedError)
        why = "it holds pickled Python objects" if "pickle" in str(e) else excerpt(str(e), 80)
        raise FileFormatError(f"{path} is not a readable .npz file ({why}); it may be truncated or "
                              f"damaged. {fix[:1].upper()}{fix[1:]}") from None
