"""Moving a whole event between stacks (laptop ↔ AWS): read it from one stack, plan and run its import on another.

Pure and typed: the stacks are the ports in `ports` (implemented by `chalicelib.storage.event_archive`), passed in;
the folder format is `chalicelib.formats.event_export`. One job per module:

* `export`: `collect_event` reads everything an event needs. Not carried: devices and their credentials (cars and
  timers re-activate on the target, into the imported fleets), live races (refused: submit or discard first),
  device commands, strip idempotency records, raw uploads and quarantined uploads, soft-deleted models.
* `import_plan`: `plan_import` decides everything, and refuses clearly, before the first write. Accounts are
  recreated with the same username (or matched by username where the target has one), and Cognito gives them new
  subs. A created account gets the racer role only: staff roles in users.json are granted only with
  `grant_roles=True` (`drem import --grant-roles`), and the report lists, per account, the roles granted and
  skipped. Matched accounts keep their own roles.
* `import_run`: `run_import` rewrites every old sub to the new one (the mapping goes into the import report) and
  `--event-id NEW` the event id the same way in the event-scoped items, has the target recompute the boards from the
  races, and writes accounts → archives → shared items (fleets, profiles, models; kept where the target already has
  them) → races → boards → the event item last, so an event only shows once its data is in. A failure part-way
  raises `PartialImport` listing exactly what was written.
* `passwords`: temporary passwords for created accounts, and the `--password-file` format.
"""
