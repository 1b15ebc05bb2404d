"""Taking a racer's upload for the league: the files they have, packed as one .tar.gz by `drem league push`, read
and assembled here on the server (never on the racer's machine, whose JSON could say anything).

The upload is hostile input: it is read in memory with the bounds of chalicelib.formats.league_export (member count,
decompressed bytes, size of each file read; unsafe names and links skipped), then assembled
(chalicelib.formats.league_assembler: every missing file is named with where the racer's tool writes it) and
checked by LeagueService.push like every submission.
"""
from __future__ import annotations

import io

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.auth.principals import Principal
from chalicelib.domain.errors import PayloadTooLarge
from chalicelib.domain.league import NAME_PATTERN, LeagueService, Submission
from chalicelib.formats.league_assembler import assemble
from chalicelib.formats.league_export import ExportFiles, ExportLimits, MiB, read_tar_gz

# An upload holds logs, metrics and evaluation sim-traces (no model graph, no checkpoints, no training sim-traces:
# the CLI leaves those out); API Gateway takes at most 10 MB per request.
MAX_UPLOAD_BYTES = 9 * MiB
UPLOAD_LIMITS = ExportLimits(max_archive_bytes=MAX_UPLOAD_BYTES, max_expanded_bytes=96 * MiB, max_members=5_000,
                             max_file_bytes=32 * MiB, max_total_read_bytes=96 * MiB)
UPLOAD_CONTENT_TYPES = ["application/gzip", "application/x-gzip", "application/octet-stream"]


class PushOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")
    racer: str | None = Field(default=None, pattern=NAME_PATTERN,
                              description="push for this racer (admins only; default: yourself)")
    model_name: str | None = Field(default=None, pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,79}$",
                                   description="the name shown on the board (default: the export's name)")


class LeagueIntake:
    def __init__(self, league: LeagueService) -> None:
        self.league = league

    def push_upload(self, principal: Principal, track: str, upload: bytes, options: PushOptions) -> Submission:
        racer = self.league.pusher(principal, options.racer)
        length_m = self.league.track_length_m(track)  # an unknown track is refused before the upload is read
        if len(upload) > MAX_UPLOAD_BYTES:
            raise PayloadTooLarge(f"the upload is larger than {MAX_UPLOAD_BYTES // MiB} MiB; push the logs, metrics "
                                  "and evaluation sim-traces only (drem league push packs just those)", field="body")
        files, names = read_tar_gz(io.BytesIO(upload), limits=UPLOAD_LIMITS)
        export = ExportFiles(options.model_name or "model", files, names)
        body = assemble(export, racer=racer, track=track, track_length_m=length_m, model_name=options.model_name)
        return self.league.push(principal, track, body)
