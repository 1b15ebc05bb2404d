"""S3 adapter for model archives in the `models` bucket: presigned upload/download, bounded reads, moves.

Keys: `uploads/{sub}/{modelId}.tar.gz` (untrusted browser upload), `models/{sub}/{modelId}.tar.gz` (validated, what
cars download), `quarantine/{sub}/{modelId}.tar.gz` (dangerous archives, never served).
"""
from __future__ import annotations

import hashlib
import tempfile
from dataclasses import dataclass
from typing import IO, Any

from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.storage.aws_errors import call, error_code, translate_common

_SERVICE = "The model file store"
_CHUNK = 1024 * 1024
# Archives up to this size stay in memory; bigger ones spill to a temporary file.
_IN_MEMORY_BYTES = 8 * 1024 * 1024
_MISSING = {"404", "NoSuchKey", "NotFound"}


@dataclass
class Download:
    """A bounded copy of an object. `too_large` means more than the limit arrived (the copy stops there)."""
    body: IO[bytes]
    size: int
    md5: str
    too_large: bool


class S3ModelFiles:
    def __init__(self, client: Any, bucket: str, presigner: Any = None) -> None:
        self._client = client
        self._bucket = bucket
        # Links for browsers and cars may need another endpoint than the app's own calls (clients.s3_presigner).
        self._presigner = presigner or client

    def presign_upload(self, key: str, *, max_bytes: int, expires_s: int) -> dict[str, Any]:
        """A presigned POST that S3 accepts only for this key and 1..max_bytes bytes (moto ignores the range)."""
        return call(self._presigner, "generate_presigned_post", _SERVICE, Bucket=self._bucket, Key=key,
                    Conditions=[["content-length-range", 1, max_bytes]], ExpiresIn=expires_s)

    def presign_download(self, key: str, *, expires_s: int) -> str:
        return call(self._presigner, "generate_presigned_url", _SERVICE, "get_object",
                    Params={"Bucket": self._bucket, "Key": key}, ExpiresIn=expires_s)

    def size_of(self, key: str) -> int | None:
        """The stored size, or None when nothing is there (yet)."""
        try:
            return int(self._client.head_object(Bucket=self._bucket, Key=key)["ContentLength"])
        except ClientError as exc:
            if error_code(exc) in _MISSING:
                return None
            raise translate_common(exc, _SERVICE) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc

    def download_bounded(self, key: str, *, limit: int) -> Download | None:
        """Stream the object into memory/a temp file, stopping after limit+1 bytes whatever the declared size."""
        try:
            stream = self._client.get_object(Bucket=self._bucket, Key=key)["Body"]
        except ClientError as exc:
            if error_code(exc) in _MISSING:
                return None
            raise translate_common(exc, _SERVICE) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc
        body = tempfile.SpooledTemporaryFile(max_size=_IN_MEMORY_BYTES)
        digest, size = hashlib.md5(usedforsecurity=False), 0
        try:
            while size <= limit:
                chunk = stream.read(min(_CHUNK, limit + 1 - size))
                if not chunk:
                    break
                body.write(chunk)
                digest.update(chunk)
                size += len(chunk)
        finally:
            stream.close()
        body.seek(0)
        return Download(body=body, size=size, md5=digest.hexdigest(), too_large=size > limit)

    def put(self, key: str, data: bytes) -> None:
        self._call("put_object", Bucket=self._bucket, Key=key, Body=data)

    def move(self, source: str, destination: str) -> None:
        self._call("copy_object", Bucket=self._bucket, Key=destination,
                   CopySource={"Bucket": self._bucket, "Key": source})
        self.delete(source)

    def copy(self, source: str, destination: str) -> None:
        self._call("copy_object", Bucket=self._bucket, Key=destination,
                   CopySource={"Bucket": self._bucket, "Key": source})

    def delete(self, key: str) -> None:
        self._call("delete_object", Bucket=self._bucket, Key=key)

    def exists(self, key: str) -> bool:
        return self.size_of(key) is not None

    def _call(self, operation: str, *args: Any, **kwargs: Any) -> Any:
        return call(self._client, operation, _SERVICE, *args, **kwargs)
