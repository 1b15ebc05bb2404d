"""The unit tests' stack, bootstrapped once per process and restored from a copy before each test that asks for it.

`ensure_stack` makes 27 AWS calls through moto (tables, buckets, user pool, client, groups): 0.06-0.15 s per test,
and most of the 3,500 unit tests ask for a stack. The state it leaves is the same every time, so the first call
runs it for real and keeps a deep copy of moto's backends; later calls put a fresh copy of that state into moto
instead. moto's own persistence works the same way: the durable local server pickles these backend objects
(drem_local.durable), so a copy behaves as the original did.

The copy is used only when moto is empty (just wiped): anything a test created before asking for the stack would
otherwise be lost, so then the stack is bootstrapped for real, as before.
"""
from __future__ import annotations

import copy
import os
from typing import Any

from moto.core.base_backend import BackendDict

from drem_infra import resources
from drem_local.bootstrap import AwsClients, StackOutputs, ensure_stack

# {key: (moto's backends after ensure_stack, its outputs)}; the key holds every input ensure_stack reads.
# The services themselves (moto's module-level BackendDicts) are kept, not copied: only their contents are.
Backends = list[tuple[BackendDict[Any], dict[str, dict[str, Any]]]]
_BOOTSTRAPPED: dict[tuple[Any, ...], tuple[Backends, StackOutputs]] = {}


def fresh_stack(clients: AwsClients, stage: str) -> StackOutputs:
    """What `ensure_stack(clients, stage)` returns and leaves in a wiped moto, at the cost of a copy."""
    if BackendDict._instances:  # moto holds something: bootstrap around it, as ensure_stack always did
        return ensure_stack(clients, stage)
    key = _inputs(clients, stage)
    if key not in _BOOTSTRAPPED:
        outputs = ensure_stack(clients, stage)
        _BOOTSTRAPPED[key] = (_copy(_backends()), outputs)
    backends, outputs = _BOOTSTRAPPED[key]
    _restore(_copy(backends))
    return outputs


def _inputs(clients: AwsClients, stage: str) -> tuple[Any, ...]:
    tables = tuple(resources.table_name(stage, spec.logical, os.environ) for spec in resources.TABLES)
    buckets = tuple(resources.bucket_name(stage, spec.logical, os.environ) for spec in resources.BUCKETS)
    return stage, clients.region, os.environ.get("MOTO_ACCOUNT_ID"), tables, buckets


def _backends() -> Backends:
    """Every service moto holds state for: [(service, {account: {region: backend}})]."""
    return [(service, {account: dict(regions) for account, regions in service.items()})
            for service in BackendDict._instances]


def _copy(backends: Backends) -> Backends:
    return [(service, copy.deepcopy(accounts)) for service, accounts in backends]


def _restore(backends: Backends) -> None:
    for service, accounts in backends:
        for account, regions in accounts.items():
            account_backends = service[account]  # registers the service as in use, so the next wipe clears it
            for region, backend in regions.items():
                dict.__setitem__(account_backends, region, backend)
