"""Which lock a storage request holds while it is journaled and run by moto: S3's own, or the one for everything else.

S3 requests move model archives of tens of megabytes; moto needs a good part of a second to store, copy or hand out
one (measured: a 21.7 MB PutObject held the single lock ~180 ms, a CopyObject ~100 ms). Under one lock, every
DynamoDB read waited behind them, so the public league board slowed while uploads were checked and re-driven
(bench/league.py, issue 32). S3 and the other services live in separate moto backends, which moto's own threaded
server runs concurrently; here each lane keeps its own requests in journal order (a request holds its lane from its
journal record until moto has answered it), so replaying the journal, in sequence order, rebuilds every backend as the
clients saw it.

The randomness of a journaled request is seeded from its record (DurableState.seed_randomness) and drawn while moto
runs it; an S3 request running at the same time must neither re-seed nor draw from that source. drem's buckets are
neither versioned nor logged nor notified, so the S3 operations it makes draw nothing; the S3 requests that do draw
(multipart uploads) and moto's own API take every lane, as before. One draw every answer makes, whatever its service,
is its request id (moto.core.responses.BaseResponse._enrich_response calls
moto.utilities.aws_headers.gen_amzn_requestid_long, which draws 52 characters from mock_random): an S3 answer in its
own lane would so shift the seeded sequence of a Cognito sign-up running at the same time, and a replay would hand
that racer another `sub`. Request ids are never state, so `Lanes()` makes them come from the operating system's
randomness instead (`request_ids_outside_the_seeded_source`).

Lock order, always: the main lane, then the S3 lane, then `state` (the journal, the dirty set and the manifest, held
only for a moment). Snapshots and recovery take all three.
"""
from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

from drem_local.durable.classify import MOTO_API, S3, needs_immediate_snapshot


def request_ids_outside_the_seeded_source() -> None:
    """Answer every request with a request id that does not draw from moto's seeded `mock_random` (idempotent)."""
    import secrets
    import string

    from moto.core import responses

    alphabet = string.ascii_letters + string.digits  # what moto draws from

    def request_id(headerdict: dict[str, Any] | None = None) -> str:
        # One read of the system's randomness per id, not one per character: 52 `secrets.choice` calls cost more
        # than moto's whole GetItem (profiled). The slight modulo bias does not matter: an id is never a secret.
        req_id = "".join(alphabet[byte % len(alphabet)] for byte in secrets.token_bytes(52))
        if isinstance(headerdict, dict):
            headerdict["x-amzn-requestid"] = req_id
        return req_id

    responses.gen_amzn_requestid_long = request_id


class Lanes:
    def __init__(self) -> None:
        request_ids_outside_the_seeded_source()
        self.main = threading.Lock()
        self.s3 = threading.Lock()
        self.state = threading.Lock()

    def locks_for(self, service: str, environ: dict[str, Any]) -> tuple[threading.Lock, ...]:
        """The lanes a request holds: S3's alone for plain S3 requests; both for those that draw randomness or
        snapshot at once; the main lane for everything else."""
        if service == S3 and not needs_immediate_snapshot(environ, service):
            return (self.s3,)
        if service in (S3, MOTO_API):
            return (self.main, self.s3)
        return (self.main,)

    @contextmanager
    def holding(self, locks: tuple[threading.Lock, ...]) -> Iterator[None]:
        with ExitStack() as stack:
            for lock in locks:
                stack.enter_context(lock)
            yield

    def everything(self) -> Any:
        """Every lane and the state: nothing runs in moto meanwhile (snapshots, recovery)."""
        return self.holding((self.main, self.s3, self.state))
