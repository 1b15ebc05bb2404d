"""A `multipart/form-data` body (an HTML form with a file input) as its text fields and files.

Read with the standard library's MIME parser (`email`, policy HTTP), which keeps a file's bytes exactly as sent.
The body is hostile input: its size is bounded before parsing, and a body that is not multipart, or has more parts
than any drem form sends, is refused with a sentence.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from email import policy
from email.message import EmailMessage
from email.parser import BytesParser

from chalicelib.core.errors import InvalidInput

MAX_BODY_BYTES = 3 * 1024 * 1024  # the largest upload a form takes (a 2 MB logo) and its fields
MAX_PARTS = 20


@dataclass(frozen=True)
class UploadedFile:
    filename: str
    content_type: str
    data: bytes


@dataclass(frozen=True)
class MultipartForm:
    fields: dict[str, str] = field(default_factory=dict)
    files: dict[str, UploadedFile] = field(default_factory=dict)


def is_multipart(content_type: str) -> bool:
    return content_type.split(";")[0].strip().lower() == "multipart/form-data"


def parsed(content_type: str, body: bytes) -> MultipartForm:
    """The form's first value per text field and first file per file input (an empty file input sends no file)."""
    if len(body) > MAX_BODY_BYTES:
        raise InvalidInput(f"The form is {len(body) / 1024 / 1024:.1f} MB; the most it takes is "
                           f"{MAX_BODY_BYTES // 1024 // 1024} MB.", field="form")
    header = content_type.replace("\r", " ").replace("\n", " ").encode("latin-1", errors="replace")
    message = BytesParser(policy=policy.HTTP).parsebytes(b"Content-Type: " + header + b"\r\n\r\n" + body)
    if not isinstance(message, EmailMessage) or not message.is_multipart():
        raise InvalidInput("The form could not be read (send it as multipart/form-data with its boundary).",
                           field="form")
    fields: dict[str, str] = {}
    files: dict[str, UploadedFile] = {}
    for count, part in enumerate(message.iter_parts(), start=1):
        if count > MAX_PARTS:
            raise InvalidInput(f"The form has more than {MAX_PARTS} parts.", field="form")
        name = part.get_param("name", header="content-disposition")
        if not isinstance(name, str) or not name:
            continue
        payload = part.get_payload(decode=True)
        data = payload if isinstance(payload, bytes) else b""
        filename = part.get_filename()
        if filename is None:
            fields.setdefault(name, data.decode("utf-8", errors="replace"))
        elif filename or data:
            files.setdefault(name, UploadedFile(filename=filename, content_type=part.get_content_type(), data=data))
    return MultipartForm(fields=fields, files=files)
