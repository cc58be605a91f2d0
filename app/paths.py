"""What a browser may open: allowed roots, sequence discovery and safe upload extraction.

Nothing typed in the browser reaches a shell or leaves the folders the server was started with.
A typed path is resolved (symlinks followed) and must lie under one of the allowed roots; an
upload is written into a fresh folder of the upload root, a zip is unpacked member by member
after checking every name (no absolute paths, no `..`, no links) and the totals.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import stat
import tempfile
import time
import zipfile
import zlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path, PurePosixPath

from autotrack.errors import InputError
from autotrack.io.frames import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS
from autotrack_studio.browser_text import readable
from autotrack_studio.owners import SPACE_PREFIX

IMAGE_SUFFIXES = IMAGE_EXTENSIONS
"""Image files a sequence folder may hold (the frame reader's list)."""
VIDEO_SUFFIXES = VIDEO_EXTENSIONS  # the frame reader opens these only
"""Video containers offered in the sequence list and accepted as uploads."""


@dataclass(frozen=True)
class UploadLimits:
    """Bounds on what one upload may contain."""

    max_upload_bytes: int = 512 * 1024**2
    """Largest uploaded file (bytes), video or zip."""
    max_members: int = 20_000
    """Most images a zip may hold."""
    max_extracted_bytes: int = 2 * 1024**3
    """Largest total size of the images unpacked from one zip (bytes)."""
    max_image_bytes: int = 64 * 1024**2
    """Largest single image in a zip (bytes)."""
    max_image_pixels: int = 40_000_000
    """Most pixels an image in a zip may have (8K is 33 million): checked from its header,
    before anything decodes it, as one decoded frame takes 3 bytes per pixel."""
    max_upload_dir_bytes: int = 8 * 1024**3
    """Quota of the uploads folder (bytes): uploads and unpacked zips together."""
    free_space_reserve: int = 256 * 1024**2
    """Disk space an upload must leave free (bytes), checked when it starts and as it is
    unpacked, so a full disk never stops the recordings."""
    idle_seconds: float = 60.0
    """An upload that sends nothing for this long is ended (its space given back)."""


def folder_bytes(folder: Path) -> int:
    """Total size of the files under `folder` (0 when it does not exist)."""
    total = 0
    for parent, _dirs, files in os.walk(folder):
        for name in files:
            with contextlib.suppress(OSError):
                total += os.lstat(os.path.join(parent, name)).st_size
    return total


def normalise_roots(roots: Iterable[str | Path]) -> tuple[Path, ...]:
    """Resolved, existing, de-duplicated folders; a missing one is an InputError."""
    resolved: list[Path] = []
    for root in roots:
        path = Path(root).resolve()
        if not path.is_dir():
            raise InputError(f"allowed root {root} is not an existing folder")
        if path not in resolved:
            resolved.append(path)
    return tuple(resolved)


def is_under(path: Path, roots: Sequence[Path]) -> bool:
    """True when the resolved `path` is one of `roots` or lies inside one."""
    return any(path == root or path.is_relative_to(root) for root in roots)


def resolve_user_path(
    text: str, roots: Sequence[Path], hides: Callable[[Path], bool] | None = None
) -> Path:
    """The existing file or folder a browser user typed, restricted to the allowed roots.

    Relative paths are taken relative to each root in turn. `~` is not expanded: the server's
    home folder is none of the user's business. A path outside the roots gets the same message
    whether or not it exists, so the browser cannot probe the server's file system; so does a
    path `hides` says is not this user's (another browser's upload).
    """
    cleaned = text.strip()
    if not cleaned:
        raise InputError("type a path to a sequence folder, an image folder or a video")
    if "\x00" in cleaned:
        raise InputError("the path contains a NUL character")
    candidates = []
    for spelling in dict.fromkeys((cleaned, _unescaped(cleaned))):  # as typed, then unescaped
        candidates += _candidates(Path(spelling), roots)
    for candidate in candidates:
        try:
            resolved = candidate.resolve(strict=True)
        except (FileNotFoundError, NotADirectoryError, RuntimeError, OSError):
            continue
        if is_under(resolved, roots) and not (hides is not None and hides(resolved)):
            return resolved
    raise InputError(
        f"{readable(_clipped(cleaned))}: no such file or folder among those this server may "
        "open; to open other folders, restart the app with --allow-root DIR"
    )


def _candidates(typed: Path, roots: Sequence[Path]) -> list[Path]:
    """Where a typed path may be: itself if absolute, else under each root, or under the root
    its first component names (as the app shows paths: `<root name>/...`)."""
    if typed.is_absolute():
        return [typed]
    candidates = [root / typed for root in roots]
    if typed.parts:
        rest = Path(*typed.parts[1:]) if len(typed.parts) > 1 else Path()
        candidates += [root / rest for root in roots if _root_label(root) == typed.parts[0]]
    return candidates


MAX_ECHOED = 120
"""The most characters of a typed text a message repeats."""


def _clipped(text: str) -> str:
    """`text`, cut to MAX_ECHOED characters (a 1 MB paste is not echoed back whole)."""
    return text if len(text) <= MAX_ECHOED else f"{text[: MAX_ECHOED - 1]}…"


def check_writable(folder: Path, what: str) -> None:
    """Refuse (InputError, one line) when no file can be created in `folder` (read-only, no
    permission), before anything that would need one is torn down."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        reason = error.strerror or type(error).__name__
        raise InputError(f"cannot write to the {what} folder {folder} ({reason})") from None


def looks_like_sequence(path: Path) -> bool:
    """A benchmark sequence folder (img/), a folder of images, or a video file."""
    if path.is_file():
        return path.suffix.lower() in VIDEO_SUFFIXES
    if not path.is_dir():
        return False
    if (path / "img").is_dir():
        return True
    try:
        return any(
            entry.is_file() and Path(entry.name).suffix.lower() in IMAGE_SUFFIXES
            for entry in os.scandir(path)
        )
    except OSError:
        return False


def find_sequences(roots: Sequence[Path], max_depth: int = 4, limit: int = 500) -> list[Path]:
    """Sequences found under the roots, in sorted order, without entering an `img/` folder.

    Stops after `limit` entries so a huge root cannot stall the GUI.
    """
    found: list[Path] = []

    def visit(folder: Path, depth: int) -> None:
        if len(found) >= limit:
            return
        if looks_like_sequence(folder):
            found.append(folder)
            return
        if depth >= max_depth:
            return
        try:
            entries = sorted(os.scandir(folder), key=lambda entry: entry.name)
        except OSError:
            return
        for entry in entries:
            if entry.name.startswith("."):
                continue
            child = Path(entry.path)
            if entry.is_dir(follow_symlinks=False):
                visit(child, depth + 1)
            elif entry.is_file() and child.suffix.lower() in VIDEO_SUFFIXES:
                found.append(child)
            if len(found) >= limit:
                return

    for root in roots:
        visit(root, 0)
    return found[:limit]


LIVE_URL_SCHEMES = ("rtsp", "rtsps", "http", "https")
"""Stream URL schemes a browser user may open as a live source (with `--allow-live`)."""
MAX_CAMERA_INDEX = 63
"""Highest camera index a browser user may open."""


def live_source(text: str, roots: Sequence[Path]) -> Path | str:
    """The live source a browser user typed: a camera index ('0'), a stream URL of one of
    LIVE_URL_SCHEMES (returned as text), or a video file under the allowed roots (played at its
    frame rate). The text reaches OpenCV only, never a shell."""
    cleaned = text.strip()
    if not cleaned:
        raise InputError("type a camera index (0), an rtsp:// or http(s):// URL, or a video file")
    if cleaned.isascii() and cleaned.isdigit():
        if int(cleaned) > MAX_CAMERA_INDEX:
            raise InputError(f"camera index {cleaned} is out of range 0..{MAX_CAMERA_INDEX}")
        return Path(str(int(cleaned)))
    scheme, separator, rest = cleaned.partition("://")
    if separator:
        if scheme.lower() not in LIVE_URL_SCHEMES:
            allowed = ", ".join(f"{name}://" for name in LIVE_URL_SCHEMES)
            raise InputError(f"{scheme}:// streams are not allowed here; use {allowed}")
        if not rest or not rest.split("/", 1)[0] or not cleaned.isprintable() or " " in cleaned:
            raise InputError(f"{cleaned!r} is not a stream URL (rtsp://HOST[:PORT]/PATH)")
        return cleaned
    path = resolve_user_path(cleaned, roots)
    if not path.is_file():
        raise InputError(f"{display_name(path, roots)} is a folder: a live source is a video file")
    return path


def _unescaped(text: str) -> str:
    """The name `readable` (app/browser_text.py) wrote as `text` (its `\\xNN` escapes back as the bytes they name)."""
    return _ESCAPED_BYTE.sub(lambda match: chr(0xDC00 + int(match.group(1), 16)), text)


_ESCAPED_BYTE = re.compile(r"\\x([89a-fA-F][0-9a-fA-F])")
"""A byte of a non-UTF-8 name as `readable` writes it (only bytes >= 0x80 are escaped)."""


def display_name(path: Path, roots: Sequence[Path]) -> str:
    """`path` relative to the root that holds it (prefixed by the root's name; a browser's
    own upload folder is named after the uploads folder that holds it), made `readable`."""
    for root in roots:
        label = _root_label(root)
        if path == root:
            return readable(label)
        if path.is_relative_to(root):
            return readable(f"{label}/{path.relative_to(root).as_posix()}")
    return readable(path.name)


def _root_label(root: Path) -> str:
    """The name a root is shown by (a browser's own upload folder: `uploads`)."""
    return root.parent.name if root.name.startswith(SPACE_PREFIX) else root.name


_ABSOLUTE_PATH = re.compile(r"(?<![\w.~-])/(?:[^\s'\"/:]+/)*([^\s'\"/:]*)")
_URL = re.compile(r"(?<![\w+.-])(?!file:)[A-Za-z][A-Za-z0-9+.-]*://[^\s'\"<>]*")
"""A URL (rtsp://host/stream, http://...): not a server path, left as it is (file:// URLs
name server files and are hidden as paths)."""


def shown_paths(text: str, roots: Sequence[Path], private: Sequence[Path] = ()) -> str:
    """`text` (a message for the browser) with the server's absolute paths hidden: a path under
    an allowed root as the app shows it (`<root name>/...`), a path under one of the `private`
    folders (sessions, incoming uploads) or anywhere else as its last component only. URLs are
    left intact."""
    named = [(root, _root_label(root)) for root in roots]
    named += [(folder.resolve(), folder.name) for folder in private]
    named.sort(key=lambda item: len(str(item[0])), reverse=True)

    def hidden(part: str) -> str:
        for folder, label in named:
            part = part.replace(str(folder), label)
        return _ABSOLUTE_PATH.sub(lambda match: match.group(1) or "/", part)

    shown, start = [], 0
    for url in _URL.finditer(text):
        shown += [hidden(text[start : url.start()]), url.group(0)]
        start = url.end()
    return readable("".join([*shown, hidden(text[start:])]))


_SAFE_NAME = re.compile(r"[^A-Za-z0-9._-]+")


def safe_file_name(name: str, fallback: str = "upload") -> str:
    """The last component of `name` reduced to letters, digits, dot, dash and underscore."""
    base = PurePosixPath(name.replace("\\", "/")).name
    cleaned = _SAFE_NAME.sub("_", base).strip("._")
    return cleaned[:120] or fallback


PARTIAL_PREFIX = ".partial-"
"""An upload being stored: hidden (never listed or opened), renamed into place once complete,
and deleted at the next start if a killed server left it."""


def new_upload_folder(upload_root: Path, label: str) -> Path:
    """A fresh, uniquely named folder under `upload_root`, still hidden (`PARTIAL_PREFIX`)."""
    upload_root.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    name = f"{PARTIAL_PREFIX}{stamp}_{safe_file_name(label)}_{secrets.token_hex(3)}"
    folder = upload_root / name
    folder.mkdir()
    return folder


def completed_upload_folder(partial: Path) -> Path:
    """Rename a stored upload's folder into place (one rename: all of it or none)."""
    folder = partial.with_name(partial.name.removeprefix(PARTIAL_PREFIX))
    partial.rename(folder)
    return folder


def remove_partial_uploads(upload_dir: Path) -> int:
    """Delete what killed servers left half-stored under `upload_dir` (and its browsers'
    folders); the count removed."""
    stale = [*upload_dir.glob(f"{PARTIAL_PREFIX}*"), *upload_dir.glob(f"*/{PARTIAL_PREFIX}*")]
    for folder in stale:
        shutil.rmtree(folder, ignore_errors=True)
    return len(stale)


def _member_problem(info: zipfile.ZipInfo) -> str | None:
    """Why a zip member must not be extracted, or None when it is safe to consider."""
    name = info.filename
    if "\x00" in name:
        return "a name with a NUL character"
    posix = PurePosixPath(name.replace("\\", "/"))
    if posix.is_absolute() or re.match(r"^[A-Za-z]:", name):
        return f"an absolute path ({name})"
    if ".." in posix.parts:
        return f"a path leaving the archive ({name})"
    mode = info.external_attr >> 16
    if stat.S_ISLNK(mode):
        return f"a symbolic link ({name})"
    return None


def extract_image_zip(
    content: bytes | Path, destination: Path, limits: UploadLimits, quota_root: Path | None = None
) -> Path:
    """Unpack the images of a zip into `destination/img/` and return that folder.

    Every member is checked before anything is written: absolute names, `..` components and
    symbolic links reject the whole archive. Non-image members (e.g. `__MACOSX/` metadata) are
    skipped. Images are renamed `000001.ext`, ... in the sorted order of their archive names,
    so the frame order is the name order and no archive name touches the filesystem. The
    declared and the actually written sizes are both held to `limits`.
    """
    try:
        archive = zipfile.ZipFile(content if isinstance(content, Path) else BytesIO(content))
    except (zipfile.BadZipFile, OSError) as error:
        raise InputError(f"the upload is not a readable zip file ({error})") from error
    with archive:
        images: list[zipfile.ZipInfo] = []
        for info in archive.infolist():
            problem = _member_problem(info)
            if problem is not None:
                raise InputError(f"refused the zip: it contains {problem}")
            if info.is_dir():
                continue
            parts = PurePosixPath(info.filename.replace("\\", "/")).parts
            if any(part.startswith(".") or part == "__MACOSX" for part in parts):
                continue
            if PurePosixPath(parts[-1]).suffix.lower() in IMAGE_SUFFIXES:
                images.append(info)
        if not images:
            raise InputError("the zip holds no images (.jpg, .png, .bmp, .tif or .webp)")
        if len(images) > limits.max_members:
            raise InputError(
                f"the zip holds {len(images)} images; the limit is {limits.max_members}"
            )
        declared = sum(info.file_size for info in images)
        if declared > limits.max_extracted_bytes:
            raise InputError(
                f"the zip unpacks to {declared / 1e6:.0f} MB; the limit is "
                f"{limits.max_extracted_bytes / 1e6:.0f} MB"
            )
        biggest = max(images, key=lambda info: info.file_size)
        if biggest.file_size > limits.max_image_bytes:
            raise InputError(
                f"refused the zip: {biggest.filename} is {biggest.file_size / 1e6:.0f} MB; "
                f"the limit per image is {limits.max_image_bytes / 1e6:.0f} MB"
            )
        room = limits.max_upload_dir_bytes - folder_bytes(quota_root or destination.parent)
        if declared > room:
            raise InputError(
                "the uploads folder would exceed its quota with this zip; "
                "ask the server's owner to clear it"
            )
        images.sort(key=lambda info: info.filename)
        image_folder = destination / "img"
        image_folder.mkdir(parents=True, exist_ok=False)
        written = 0
        for index, info in enumerate(images, start=1):
            suffix = PurePosixPath(info.filename).suffix.lower()
            target = image_folder / f"{index:06d}{suffix}"
            try:
                with archive.open(info) as source, open(target, "xb") as sink:
                    chunk = source.read(1 << 20)
                    _check_pixels(info.filename, chunk, limits)
                    while chunk:
                        written += len(chunk)
                        if written > limits.max_extracted_bytes:
                            raise InputError("the zip unpacks to more than it declares; refused")
                        _check_room(image_folder, len(chunk), limits)
                        sink.write(chunk)
                        chunk = source.read(1 << 20)
            except (zipfile.BadZipFile, zlib.error, EOFError) as error:
                raise InputError(f"the zip is damaged at {info.filename} ({error})") from error
            except OSError as error:
                reason = error.strerror or type(error).__name__
                raise InputError(f"cannot unpack the zip on the server ({reason})") from None
    return image_folder


def _check_room(folder: Path, size: int, limits: UploadLimits) -> None:
    """Refuse to write `size` more bytes into `folder` when the disk would keep less than the
    reserve free."""
    if shutil.disk_usage(folder).free - size < limits.free_space_reserve:
        raise InputError(
            "the server's disk is nearly full: the zip was not unpacked; ask the server's "
            "owner to free space"
        )


def _check_pixels(name: str, head: bytes, limits: UploadLimits) -> None:
    """Refuse an image whose header (the first bytes of the file) is unreadable or declares
    more pixels than the limit, before anything decodes it."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(BytesIO(head)) as image:
            width, height = image.size
    except Image.DecompressionBombError as error:  # PIL's own, far higher, limit
        raise InputError(
            f"refused the zip: {name} has more than "
            f"{limits.max_image_pixels / 1e6:.0f} million pixels"
        ) from error
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as error:
        raise InputError(f"refused the zip: {name} is not a readable image") from error
    if width * height > limits.max_image_pixels:
        raise InputError(
            f"refused the zip: {name} is {width}x{height} pixels; the limit is "
            f"{limits.max_image_pixels / 1e6:.0f} million pixels per image"
        )


def store_upload(
    file_name: str,
    content: bytes | Path,
    upload_root: Path,
    limits: UploadLimits,
    *,
    quota_root: Path | None = None,
) -> Path:
    """Put an uploaded video or zip of images under `upload_root`; return what to open.

    `content` is the file's bytes or a received file (moved, not copied). A video is kept as
    is under a sanitised name; a zip is unpacked by `extract_image_zip`, its size held to the
    quota of `quota_root` (default `upload_root`). A refused upload leaves nothing under
    `upload_root`.
    """
    size = content.stat().st_size if isinstance(content, Path) else len(content)
    if size == 0:
        raise InputError("the uploaded file is empty")
    if size > limits.max_upload_bytes:
        raise InputError(
            f"the upload is {size / 1e6:.0f} MB; the limit is "
            f"{limits.max_upload_bytes / 1e6:.0f} MB"
        )
    name = safe_file_name(file_name)
    suffix = Path(name).suffix.lower()
    if suffix == ".zip" or suffix in VIDEO_SUFFIXES:
        folder = new_upload_folder(upload_root, Path(name).stem)
        try:
            if suffix == ".zip":
                extract_image_zip(content, folder, limits, quota_root or upload_root)
                return completed_upload_folder(folder)
            if isinstance(content, Path):
                shutil.move(content, folder / name)
            else:
                with open(folder / name, "xb") as sink:
                    sink.write(content)
            return completed_upload_folder(folder) / name
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
    raise InputError(
        f"cannot use {file_name!r}: upload a video ({', '.join(sorted(VIDEO_SUFFIXES))}) "
        "or a .zip of images"
    )
