"""Blob stores: immutable byte objects under string keys, on a local directory or on S3.

Keys default to the SHA-256 hex of the content (``put`` without a key), so writing the same result twice
(a retried attempt) stores one object. Local writes are atomic (temp file + ``os.replace``).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Protocol
from urllib.parse import urlparse

from ..settings import Settings

_CHUNK = 1 << 20


class BlobNotFound(KeyError):
    """No blob under that key."""


class BlobStore(Protocol):
    """The interface both stores implement."""

    def put(self, data: bytes, key: str | None = None) -> str:
        """Store bytes under ``key`` (default: their SHA-256); returns the key."""
        ...

    def put_file(self, path: Path, key: str | None = None) -> str:
        """Store a file's content without reading it into memory; returns the key."""
        ...

    def put_if_absent(self, data: bytes, key: str) -> bool:
        """Store ``data`` under ``key`` only if no blob is there yet (first writer wins); True if stored."""
        ...

    def get(self, key: str) -> bytes:
        """The bytes under ``key``; BlobNotFound if absent."""
        ...

    def get_range(self, key: str, start: int, length: int) -> bytes:
        """``length`` bytes of the blob under ``key`` from byte ``start`` (a window's frames of raw poses)."""
        ...

    def get_file(self, key: str, path: Path) -> None:
        """Write the blob under ``key`` to the file ``path`` without reading it into memory."""
        ...

    def exists(self, key: str) -> bool:
        """Whether ``key`` is stored."""
        ...

    def delete(self, key: str) -> None:
        """Remove ``key`` (no error if absent)."""
        ...

    def ping(self) -> None:
        """Raise if the store cannot be reached."""
        ...

    def keys(self, before: float) -> Iterator[str]:
        """Every key stored (or last stored again) before epoch time ``before`` (for the sweeper)."""
        ...

    def remove_temp_files(self, before: float) -> int:
        """Remove temporary files of writes that began before ``before`` and never finished; how many."""
        ...


def content_key(data: bytes) -> str:
    """The content-hash key of ``data``."""
    return hashlib.sha256(data).hexdigest()


def file_key(path: Path) -> str:
    """The content-hash key of a file, read in chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def _check_key(key: str) -> str:
    if not key or key.startswith("/") or ".." in key.split("/") or "\\" in key:
        raise ValueError(f"invalid blob key {key!r}")
    return key


class LocalBlobStore:
    """Blobs as files under a directory, sharded by the key's first two characters."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def _path(self, key: str) -> Path:
        key = _check_key(key)
        return self.root / key[:2] / key

    def _temp_file(self, target: Path, fill) -> str:  # noqa: ANN001 - fill(fileobj) writes the content
        """A finished, fsynced temporary file beside ``target`` (same filesystem, so rename/link is
        atomic)."""
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".tmp-")
        try:
            with os.fdopen(fd, "wb") as fh:
                fill(fh)
                fh.flush()
                os.fsync(fh.fileno())
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return tmp

    def _write_atomic(self, key: str, fill) -> str:  # noqa: ANN001 - fill(fileobj) writes the content
        target = self._path(key)
        try:
            os.utime(target)  # stored already: now counts as its last store (the sweeper's grace)
            return key
        except FileNotFoundError:
            pass
        tmp = self._temp_file(target, fill)
        try:
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return key

    def put(self, data: bytes, key: str | None = None) -> str:
        """Store ``data``; returns its key (content hash unless given)."""
        return self._write_atomic(key or content_key(data), lambda fh: fh.write(data))

    def put_file(self, path: Path, key: str | None = None) -> str:
        """Store a file's content without loading it whole."""
        def copy(fh) -> None:  # noqa: ANN001
            with open(path, "rb") as src:
                shutil.copyfileobj(src, fh, _CHUNK)
        return self._write_atomic(key or file_key(path), copy)

    def put_if_absent(self, data: bytes, key: str) -> bool:
        """Store ``data`` under ``key`` unless a blob is there (hard link of a finished temp file: atomic,
        first writer wins even between processes); True if this call stored it."""
        target = self._path(key)
        if target.exists():
            return False
        tmp = self._temp_file(target, lambda fh: fh.write(data))
        try:
            os.link(tmp, target)
            return True
        except FileExistsError:
            return False
        finally:
            Path(tmp).unlink(missing_ok=True)

    def get(self, key: str) -> bytes:
        """The bytes under ``key``; BlobNotFound if absent."""
        try:
            return self._path(key).read_bytes()
        except FileNotFoundError as exc:
            raise BlobNotFound(key) from exc

    def get_range(self, key: str, start: int, length: int) -> bytes:
        """``length`` bytes from byte ``start`` (fewer at the end of the blob); BlobNotFound if absent."""
        try:
            with open(self._path(key), "rb") as fh:
                fh.seek(start)
                return fh.read(length)
        except FileNotFoundError as exc:
            raise BlobNotFound(key) from exc

    def get_file(self, key: str, path: Path) -> None:
        """Copy the blob under ``key`` to ``path``; BlobNotFound if absent."""
        try:
            shutil.copyfile(self._path(key), path)
        except FileNotFoundError as exc:
            raise BlobNotFound(key) from exc

    def exists(self, key: str) -> bool:
        """Whether a blob is stored under ``key``."""
        return self._path(key).is_file()

    def delete(self, key: str) -> None:
        """Remove the blob (no error if absent)."""
        self._path(key).unlink(missing_ok=True)

    def ping(self) -> None:
        """Raise if the directory is not writable."""
        if not os.access(self.root, os.W_OK):
            raise OSError(f"blob directory {self.root} is not writable")

    def _files(self) -> Iterator[tuple[Path, str]]:
        """(path, key) of every file under the shard directories, temporary files included."""
        for shard in sorted(self.root.iterdir()):
            if shard.is_dir():
                for folder, _, names in os.walk(shard):
                    for name in names:
                        path = Path(folder) / name
                        yield path, path.relative_to(shard).as_posix()

    def keys(self, before: float) -> Iterator[str]:
        """Every key whose file was last stored before ``before``."""
        for path, key in self._files():
            try:
                if not path.name.startswith(".tmp-") and path.stat().st_mtime < before:
                    yield key
            except FileNotFoundError:
                continue  # removed meanwhile

    def remove_temp_files(self, before: float) -> int:
        """Remove ``.tmp-*`` files older than ``before`` (writes of a killed process)."""
        removed = 0
        for path, _ in self._files():
            try:
                if path.name.startswith(".tmp-") and path.stat().st_mtime < before:
                    path.unlink()
                    removed += 1
            except FileNotFoundError:
                continue
        return removed


class S3BlobStore:
    """Blobs as objects in an S3 bucket under a prefix (boto3; endpoint configurable for MinIO/moto)."""

    def __init__(
        self, bucket: str, prefix: str = "", endpoint_url: str | None = None, region: str = "us-east-1"
    ):
        import boto3  # only the S3 store needs it

        self.bucket, self.prefix = bucket, prefix.strip("/")
        self.client = boto3.client("s3", endpoint_url=endpoint_url, region_name=region)

    def _name(self, key: str) -> str:
        key = _check_key(key)
        return f"{self.prefix}/{key}" if self.prefix else key

    def put(self, data: bytes, key: str | None = None) -> str:
        """Store ``data``; returns its key (content hash unless given)."""
        key = key or content_key(data)
        self.client.put_object(Bucket=self.bucket, Key=self._name(key), Body=data)
        return key

    def put_file(self, path: Path, key: str | None = None) -> str:
        """Upload a file (multipart for large files) under its content hash unless a key is given, with at
        most two 8 MiB parts in flight (boto3's default, ten, holds 80 MiB per upload in the API)."""
        from boto3.s3.transfer import TransferConfig

        key = key or file_key(path)
        if Path(path).stat().st_size <= 8 * _CHUNK:  # one PUT: the transfer manager's threads cost more
            with open(path, "rb") as fh:
                self.client.put_object(Bucket=self.bucket, Key=self._name(key), Body=fh)
            return key
        config = TransferConfig(multipart_chunksize=8 * _CHUNK, max_concurrency=2)
        self.client.upload_file(str(path), self.bucket, self._name(key), Config=config)
        return key

    def put_if_absent(self, data: bytes, key: str) -> bool:
        """Conditional PUT (``If-None-Match: *``): S3 stores it only if the key is free; True if stored."""
        from botocore.exceptions import ClientError

        try:
            self.client.put_object(Bucket=self.bucket, Key=self._name(key), Body=data, IfNoneMatch="*")
            return True
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in (
                "PreconditionFailed",
                "ConditionalRequestConflict",
                "412",
                "409",
            ):
                return False
            raise

    def get(self, key: str) -> bytes:
        """The bytes under ``key``; BlobNotFound if absent."""
        from botocore.exceptions import ClientError

        try:
            return self.client.get_object(Bucket=self.bucket, Key=self._name(key))["Body"].read()
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in ("NoSuchKey", "404"):
                raise BlobNotFound(key) from exc
            raise

    def get_range(self, key: str, start: int, length: int) -> bytes:
        """``length`` bytes from byte ``start`` (a ranged GET); BlobNotFound if absent."""
        from botocore.exceptions import ClientError

        if length <= 0:
            return b""
        try:
            return self.client.get_object(Bucket=self.bucket, Key=self._name(key),
                                          Range=f"bytes={start}-{start + length - 1}")["Body"].read()
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in ("NoSuchKey", "404"):
                raise BlobNotFound(key) from exc
            raise

    def get_file(self, key: str, path: Path) -> None:
        """Download the blob under ``key`` to ``path``; BlobNotFound if absent."""
        from botocore.exceptions import ClientError

        try:
            self.client.download_file(self.bucket, self._name(key), str(path))
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in ("NoSuchKey", "404"):
                raise BlobNotFound(key) from exc
            raise

    def exists(self, key: str) -> bool:
        """Whether an object is stored under ``key``."""
        from botocore.exceptions import ClientError

        try:
            self.client.head_object(Bucket=self.bucket, Key=self._name(key))
            return True
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in ("NoSuchKey", "404", "NotFound"):
                return False
            raise

    def delete(self, key: str) -> None:
        """Remove the object (no error if absent)."""
        self.client.delete_object(Bucket=self.bucket, Key=self._name(key))

    def ping(self) -> None:
        """Raise if the bucket cannot be reached."""
        self.client.head_bucket(Bucket=self.bucket)

    def keys(self, before: float) -> Iterator[str]:
        """Every key under the prefix whose object was last written before ``before`` (paginated listing)."""
        start = f"{self.prefix}/" if self.prefix else ""
        for page in self.client.get_paginator("list_objects_v2").paginate(Bucket=self.bucket, Prefix=start):
            for item in page.get("Contents", []):
                if item["LastModified"].timestamp() < before:
                    yield item["Key"][len(start):]

    def remove_temp_files(self, before: float) -> int:
        """Nothing to do: an S3 object appears whole or not at all (unfinished multipart uploads are the
        bucket's lifecycle rules' to abort)."""
        return 0


def open_blob_store(settings: Settings) -> LocalBlobStore | S3BlobStore:
    """The blob store named by ``settings.blob_url`` (file://DIR or s3://BUCKET/PREFIX)."""
    url = settings.resolved_blob_url()
    parsed = urlparse(url)
    if parsed.scheme == "file":
        return LocalBlobStore(Path(parsed.netloc + parsed.path))
    if parsed.scheme == "s3":
        return S3BlobStore(parsed.netloc, parsed.path, settings.s3_endpoint_url, settings.s3_region)
    raise ValueError(f"unsupported PDEANIM_BLOB_URL {url!r}: use file:///dir or s3://bucket/prefix")
