"""The `drem-event-export` folder (version 1): one event, moved between stacks (laptop ↔ AWS).

    manifest.json       format, version, event id, `exported_at`, sha256 + md5 + size of every other file
    event.json          the event item                          (table `events`)
    races.json          its finished races with their laps,     (table `races`)
                        and the audit trail of results changes
    leaderboards.json   its materialised boards and overlays    (table `leaderboards`)
    profiles.json       the racers' public profiles + name alias (table `profiles`)
    fleets.json         the fleets its tracks use               (table `fleet`, fleet items only)
    models.json         the model records of its people         (table `models`, record + id pointer)
    users.json          the accounts: username, old sub, email, country, roles, enabled
    archives.json       model id → archive key, file and md5
    archives/<model_id>.tar.gz   the validated model archives, byte for byte

Items are stored as DynamoDB attribute values (`{"S": ...}`), so an export is lossless and never depends on how
the app parses them today. Content files are deterministic (sorted keys, items sorted by key, no run timestamps):
only `manifest.json`'s `exported_at` says when.

One job per module: `records` (the folder's names and records), `writer` (writing a folder), `reader` (reading and
checking one: checksums, layout, item shapes), `checks` (re-validating every item and archive the app will trust),
`remap` (rewriting subs and the event id). Moving an event (reading a stack, planning and running an import) is
`chalicelib.domain.event_transfer`.
"""
