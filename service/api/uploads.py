"""Streaming multipart upload: the ``file`` part goes to a temp file in chunks, and the size limit is
enforced while the body is being read (413 as soon as it is passed), never after buffering it whole."""

from __future__ import annotations

import asyncio
import os
import tempfile
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

from fastapi import Request
from python_multipart.exceptions import MultipartParseError
from python_multipart.multipart import MultipartParser, parse_options_header

from ..store.scratch import prefix
from .errors import ApiError
from .uploadslots import BodyPace

FORM_OVERHEAD = 64 * 1024  # boundaries, part headers and small extra fields

UPLOAD_BODY = {"requestBody": {"required": True, "content": {"multipart/form-data": {"schema": {
    "type": "object", "required": ["file"],
    "properties": {"file": {"type": "string", "format": "binary"}}}}}}}
"""OpenAPI description of the multipart body (the route reads the stream itself)."""


@dataclass
class Upload:
    """An uploaded file on disk; the caller deletes ``path``."""

    path: Path
    filename: str
    size: int


def _text(raw: bytes) -> str:
    """A multipart parameter as text: UTF-8 (what browsers and curl send), else Latin-1 (never fails)."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _too_large(limit: int) -> ApiError:
    return ApiError(413, "payload_too_large", f"upload is larger than the limit of {limit} bytes "
                                              "(setting PDEANIM_MAX_UPLOAD_BYTES)")


class _FilePart:
    """Parser callbacks that write the part named ``field`` to a temp file and count its bytes."""

    def __init__(self, field: str, tmp_dir: Path, limit: int):
        self.field, self.tmp_dir, self.limit = field, tmp_dir, limit
        self.headers: dict[bytes, bytes] = {}
        self._name = self._value = b""
        self.fh = None
        self.upload: Upload | None = None

    def callbacks(self) -> dict:
        """The callback table of python-multipart's MultipartParser."""
        return {"on_part_begin": self.begin, "on_header_field": self.hfield, "on_header_value": self.hvalue,
                "on_header_end": self.hend, "on_headers_finished": self.headers_done,
                "on_part_data": self.data, "on_part_end": self.end}

    def begin(self) -> None:
        """A new part starts."""
        self.headers = {}

    def hfield(self, data: bytes, start: int, end: int) -> None:
        """More of a header name."""
        self._name += data[start:end]

    def hvalue(self, data: bytes, start: int, end: int) -> None:
        """More of a header value."""
        self._value += data[start:end]

    def hend(self) -> None:
        """A header is complete (kept as bytes: names and filenames are UTF-8, not Latin-1, in practice)."""
        self.headers[self._name.lower()] = self._value
        self._name = self._value = b""

    def headers_done(self) -> None:
        """Headers complete: open the temp file if this is the wanted field."""
        _, params = parse_options_header(self.headers.get(b"content-disposition", b""))
        if _text(params.get(b"name", b"")) == self.field and self.upload is None:
            filename = os.path.basename(_text(params.get(b"filename", b"upload")).replace("\\", "/"))
            fd, path = tempfile.mkstemp(dir=self.tmp_dir, prefix=prefix("upload"))
            self.fh = os.fdopen(fd, "wb")
            self.upload = Upload(Path(path), filename or "upload", 0)

    def data(self, data: bytes, start: int, end: int) -> None:
        """Part data: counted against the limit, written to the temp file."""
        if self.fh is None:
            return
        self.upload.size += end - start
        if self.upload.size > self.limit:
            raise _too_large(self.limit)
        self.fh.write(data[start:end])

    def end(self) -> None:
        """The part is complete."""
        if self.fh is not None:
            self.fh.close()
            self.fh = None


async def _paced(request: Request, pace: BodyPace) -> AsyncIterator[bytes]:
    """The body's chunks, or a 408 as soon as it falls behind ``pace``."""
    started, received = time.monotonic(), 0
    chunks = request.stream().__aiter__()
    while True:
        left = pace.seconds_left(started, received)
        try:
            chunk = await (anext(chunks) if left is None else asyncio.wait_for(anext(chunks), max(left, 0)))
        except StopAsyncIteration:
            return
        except TimeoutError:
            raise pace.too_slow(started, received) from None
        received += len(chunk)
        yield chunk


async def receive_file(request: Request, tmp_dir: Path, limit: int, pace: BodyPace,
                       field: str = "file") -> Upload:
    """Read a multipart/form-data body, keeping the ``field`` file part on disk (at most ``limit`` bytes,
    arriving at least at ``pace``)."""
    ctype, params = parse_options_header(request.headers.get("content-type", ""))
    if ctype != b"multipart/form-data" or not params.get(b"boundary"):
        raise ApiError(415, "unsupported_media_type",
                       f"send the file as multipart/form-data in a field named {field!r}")
    declared = request.headers.get("content-length")
    if declared and declared.isdigit() and int(declared) > limit + FORM_OVERHEAD:
        raise _too_large(limit)
    part = _FilePart(field, tmp_dir, limit)
    parser = MultipartParser(params[b"boundary"], part.callbacks())
    received = 0
    try:
        async for chunk in _paced(request, pace):
            received += len(chunk)
            if received > limit + FORM_OVERHEAD:
                raise _too_large(limit)
            parser.write(chunk)
        parser.finalize()
    except MultipartParseError as exc:
        discard(part)
        raise ApiError(400, "bad_request", f"malformed multipart body: {exc}") from exc
    except BaseException:
        discard(part)
        raise
    if part.fh is not None or part.upload is None:
        discard(part)
        raise ApiError(400, "bad_request", f"multipart body has no complete file field named {field!r}")
    if part.upload.size == 0:
        discard(part)
        raise ApiError(422, "empty_upload", "the uploaded file is empty")
    return part.upload


def discard(part: _FilePart) -> None:
    """Close and delete a partially received file."""
    if part.fh is not None:
        part.fh.close()
        part.fh = None
    if part.upload is not None:
        part.upload.path.unlink(missing_ok=True)
