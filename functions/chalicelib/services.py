"""The composition root: the one place that builds domain services from storage adapters, settings and the clock.

Routes, auth and the CLI ask here for what they need (`services.race_service()`), so no route module imports another
to borrow its wiring. Everything is built per call: settings are read lazily (Chalice sets them only while a handler
runs) and boto3 clients are built once, on first use (`storage/clients.py`), so building a service costs a few object
allocations and nothing at import.

Tests replace the clock with `monkeypatch.setattr(services, "now_ms", ...)`: every builder reads `now_ms` at call time.
"""
from __future__ import annotations

import functools
import importlib.util
import time
from datetime import UTC, datetime
from typing import Any

from chalicelib import live_wake
from chalicelib.auth.revocation import REVOKED
from chalicelib.auth.sessions import use_session_backends
from chalicelib.core.errors import ServiceUnavailable
from chalicelib.domain.activation import ActivationService
from chalicelib.domain.assignment_signals import AssignmentSignals
from chalicelib.domain.assignments import AssignmentService
from chalicelib.domain.big_screen import ScreenPublisher
from chalicelib.domain.booth_drive import DriveService, LiveDrives
from chalicelib.domain.booth_runs import RunService
from chalicelib.domain.booth_tracks import TrackService
from chalicelib.domain.booth_training import TrainingService
from chalicelib.domain.devices import DeviceService
from chalicelib.domain.event_logos import EventLogoService
from chalicelib.domain.events import EventService
from chalicelib.domain.fleets import FleetService
from chalicelib.domain.leaderboards import LeaderboardPublisher, PublicViewCache
from chalicelib.domain.league import LeagueService
from chalicelib.domain.league_intake import LeagueIntake
from chalicelib.domain.model_conversion import ConsoleConverter
from chalicelib.domain.model_registry import RegistryService, lineage_from_archive
from chalicelib.domain.model_scrutiny import ScrutineerService, ScrutinyEnqueuer, upcoming_track_types
from chalicelib.domain.on_deck import OnDeck
from chalicelib.domain.passwords import PasswordService
from chalicelib.domain.profiles import ProfileService, ProfilesForBoards
from chalicelib.domain.racer_models import ModelRecord, ModelService, ModelStatus
from chalicelib.domain.racer_queue import RacerQueueService
from chalicelib.domain.races import RaceService
from chalicelib.domain.scrutineer_queue import ScrutineerQueue
from chalicelib.domain.stats import StatsDigests
from chalicelib.domain.timing import TimingService
from chalicelib.domain.users import ModelsEraser, OwnedDataEraser, UserService
from chalicelib.settings import Settings, get_settings, use_parameter_reader
from chalicelib.storage import clients, health, parameters
from chalicelib.storage.assignments import DynamoAssignmentStore, FleetCarDirectory
from chalicelib.storage.audit import DynamoAuditLog
from chalicelib.storage.booth import DynamoBoothStore
from chalicelib.storage.cognito import CognitoIdentityProvider
from chalicelib.storage.devices import DynamoDeviceStore
from chalicelib.storage.evaluations import DynamoEvaluationStore
from chalicelib.storage.event_logos import DynamoLogoStore
from chalicelib.storage.events import DynamoEventStore, DynamoLiveRaceProbe
from chalicelib.storage.fleets import DynamoFleetStore
from chalicelib.storage.leaderboards import DynamoBoardStore
from chalicelib.storage.league import DynamoLeagueStore
from chalicelib.storage.model_files import S3ModelFiles
from chalicelib.storage.passwords import CognitoPasswordChanger
from chalicelib.storage.profiles import DynamoProfileStore
from chalicelib.storage.race_stats import DynamoStatsDigestStore
from chalicelib.storage.racer_models import DynamoModelStore, EventTrackTypes
from chalicelib.storage.racer_queue import DynamoQueueStore
from chalicelib.storage.races import DynamoRaceStore
from chalicelib.storage.scrutineer_queue import LEAGUE_QUEUE_PK, DynamoJobStore
from chalicelib.storage.sessions import DynamoSessionStore
from chalicelib.storage.users import CognitoUserDirectory

# On AWS the public URL may live in the stack's SSM parameter (chalicelib.settings.get_settings reads it).
use_parameter_reader(parameters.read_parameter)


def now_ms() -> int:
    """The app's clock: milliseconds since the epoch."""
    return time.time_ns() // 1_000_000


def probe_storage() -> str:
    """'ok', 'missing' or 'unreachable': can the app reach its storage (what /healthz checks)."""
    return health.probe_table(clients.dynamodb(), get_settings().table("events"))


# --- accounts and sessions ------------------------------------------------------------------------------------------

def _require_user_pool(settings: Settings, what: str) -> tuple[str, str]:
    """(user pool id, app client id), or ServiceUnavailable when either is not configured."""
    if not settings.user_pool_id or not settings.user_pool_client_id:
        raise ServiceUnavailable(f"{what} not configured (DREM_USER_POOL_ID / DREM_USER_POOL_CLIENT_ID).")
    return settings.user_pool_id, settings.user_pool_client_id


def identity_provider(settings: Settings | None = None) -> CognitoIdentityProvider:
    settings = settings or get_settings()
    pool_id, client_id = _require_user_pool(settings, "Sign-in is")
    return CognitoIdentityProvider(clients.cognito(), pool_id, client_id)


def user_directory(settings: Settings | None = None) -> CognitoUserDirectory:
    settings = settings or get_settings()
    pool_id, client_id = _require_user_pool(settings, "Accounts are")
    return CognitoUserDirectory(clients.cognito(), pool_id, client_id)


def session_store() -> DynamoSessionStore:
    return DynamoSessionStore(clients.dynamodb(), get_settings().table("sessions"))


def password_service() -> PasswordService:
    return PasswordService(CognitoPasswordChanger(clients.cognito()))


class RevokingSessions:
    """UserService's SessionEnder: marks the user's tokens revoked (chalicelib.auth.revocation)."""

    def ended(self, sub: str) -> None:
        REVOKED.ended(session_store(), sub)

    def reopened(self, sub: str) -> None:
        REVOKED.reopened(session_store(), sub)

    def roles_changed(self, sub: str, groups: frozenset[str]) -> None:
        REVOKED.roles_changed(session_store(), sub, groups)


def owned_data_erasers() -> tuple[OwnedDataEraser, ...]:
    """What self-delete must clear besides the profile: the user's models."""
    return (ModelsEraser(model_service()),)


def user_service() -> UserService:
    return UserService(user_directory(), profile_service(), owned_data_erasers(),
                       confirm_sign_ups=get_settings().local_identity, sessions=RevokingSessions())


def profile_store() -> DynamoProfileStore:
    return DynamoProfileStore(clients.dynamodb(), get_settings().table("profiles"))


def profile_service() -> ProfileService:
    """Profiles with the account directory behind them (for changes that touch the account); a change is shown on
    every board the racer is on."""
    return ProfileService(profile_store(), user_directory(), boards=race_service())


def public_profiles() -> ProfileService:
    """Profiles for reading public views only: no account directory needed (boards, results)."""
    return ProfileService(profile_store())


def league_shown_names(usernames: list[str]) -> dict[str, str]:
    """What the public league board shows for its racers, read at most a few seconds ago (domain.shown_names_cache)."""
    from chalicelib.domain.shown_names_cache import PROCESS_SHOWN_NAMES

    return PROCESS_SHOWN_NAMES.get(usernames, public_profiles().shown_names)


# --- events, fleets and devices -------------------------------------------------------------------------------------

def event_store() -> DynamoEventStore:
    return DynamoEventStore(clients.dynamodb(), get_settings().table("events"))


def event_service() -> EventService:
    settings, dynamodb = get_settings(), clients.dynamodb()
    return EventService(event_store(), DynamoLiveRaceProbe(dynamodb, settings.table("races")),
                        DynamoFleetStore(dynamodb, settings.table("fleet")), now_ms,
                        on_saved=screen_publisher().publish)


def logo_store() -> DynamoLogoStore:
    return DynamoLogoStore(clients.dynamodb(), get_settings().table("events"))


def event_logo_service() -> EventLogoService:
    return EventLogoService(event_store(), logo_store(), on_changed=screen_publisher().publish)


def screen_publisher() -> ScreenPublisher:
    """Publishes the big screen's settings after an event or logo edit (open screens show it without a reload)."""
    def logo_version(event_id: str) -> str | None:
        found = logo_store().version(event_id)
        return found.version if found else None

    return ScreenPublisher(publisher(), logo_version)


def device_store() -> DynamoDeviceStore:
    return DynamoDeviceStore(clients.dynamodb(), get_settings().table("fleet"))


def fleet_store() -> DynamoFleetStore:
    return DynamoFleetStore(clients.dynamodb(), get_settings().table("fleet"))


def fleet_service() -> FleetService:
    return FleetService(fleet_store(), device_store(), now_ms)


def device_service() -> DeviceService:
    return DeviceService(device_store(), fleet_store(), clock_ms=now_ms)


def activation_service() -> ActivationService:
    return ActivationService(device_store(), fleet_store(), clock_ms=now_ms)


# --- races, boards and timing ---------------------------------------------------------------------------------------

def race_store() -> DynamoRaceStore:
    return DynamoRaceStore(clients.dynamodb(), get_settings().table("races"))


def publisher() -> LeaderboardPublisher:
    return LeaderboardPublisher(DynamoBoardStore(clients.dynamodb(), get_settings().table("leaderboards")), now_ms,
                                on_change=live_wake.waker(get_settings()))


def live_publisher(cache: PublicViewCache) -> LeaderboardPublisher:
    """For the live server (drem_live): its own read cache, which it empties for an event when the writer wakes it
    (PublicViewCache.invalidate_event), so every channel and poll of that event woken together shares one read of
    each item instead of reading it once per channel."""
    return LeaderboardPublisher(DynamoBoardStore(clients.dynamodb(), get_settings().table("leaderboards")), now_ms,
                                cache=cache)


def audit_log() -> DynamoAuditLog:
    return DynamoAuditLog(clients.dynamodb(), get_settings().table("races"))


def stats_digests() -> StatsDigests:
    return StatsDigests(DynamoStatsDigestStore(clients.dynamodb(), get_settings().table("races")), race_store(), now_ms)


def race_service() -> RaceService:
    return RaceService(race_store(), event_store(), user_directory(), ProfilesForBoards(public_profiles()),
                       publisher(), now_ms, audit=audit_log(), stats=stats_digests())


def timing_service() -> TimingService:
    return TimingService(race_service(), race_store(), device_store(), now_ms, events=event_store())


# --- models, cars and the league ------------------------------------------------------------------------------------

@functools.cache
def console_converter() -> ConsoleConverter:
    """One per process: it keeps a spare conversion worker ready across requests (see ConsoleConverter)."""
    return ConsoleConverter(keep_spare=True)


def model_service(settings: Settings | None = None, **options: Any) -> ModelService:
    """The model service over the configured table and bucket (clients built lazily, on first use)."""
    settings = settings or get_settings()
    options.setdefault("converter", console_converter())
    options.setdefault("scrutineer_queue", scrutiny_enqueuer(settings))
    return ModelService(DynamoModelStore(clients.dynamodb(), settings.table("models")),
                        S3ModelFiles(clients.s3(), settings.bucket("models"), clients.s3_presigner()), **options)


def registry_service(settings: Settings | None = None) -> RegistryService:
    settings = settings or get_settings()
    models = model_service(settings)
    return RegistryService(models, DynamoEvaluationStore(clients.dynamodb(), settings.table("models")),
                           lineage_from_archive(models, models.max_upload_bytes))


def scrutineer_service(settings: Settings | None = None) -> ScrutineerService:
    settings = settings or get_settings()
    return ScrutineerService(model_service(settings),
                             EventTrackTypes(DynamoEventStore(clients.dynamodb(), settings.table("events"))),
                             queue=scrutineer_queue(settings))


def scrutineer_queue(settings: Settings | None = None) -> ScrutineerQueue:
    settings = settings or get_settings()
    return ScrutineerQueue(DynamoJobStore(clients.dynamodb(), settings.table("models")), now_ms)


def scrutiny_enqueuer(settings: Settings | None = None) -> ScrutinyEnqueuer | None:
    """New AVAILABLE models are queued for a background drive on the upcoming events' track types, where a worker
    can drive them: the simulator is installed (the local stack), or the settings say a worker runs elsewhere (on AWS
    with the learning booth's task). Otherwise (the Lambda bundle has no simulator) nothing is queued, and models stay
    "not scrutineered" instead of "queued" for ever."""
    settings = settings or get_settings()
    if importlib.util.find_spec("drem_sim") is None and not settings.scrutineering_worker:
        return None
    events = DynamoEventStore(clients.dynamodb(), settings.table("events"))
    today = lambda: datetime.fromtimestamp(now_ms() / 1000, UTC).date()  # noqa: E731 - read at call time
    return ScrutinyEnqueuer(scrutineer_queue(settings), lambda: upcoming_track_types(events.list(), today()))


def assignment_service(settings: Settings | None = None) -> AssignmentService:
    settings = settings or get_settings()
    fleet_table, dynamodb = settings.table("fleet"), clients.dynamodb()
    directory = FleetCarDirectory(DynamoDeviceStore(dynamodb, fleet_table),
                                  DynamoEventStore(dynamodb, settings.table("events")))
    return AssignmentService(DynamoAssignmentStore(dynamodb, fleet_table), model_service(settings), directory,
                             signals=assignment_signals(), recheck_s=settings.assignment_recheck_s)


@functools.cache
def assignment_signals() -> AssignmentSignals:
    """One per process: every request thread's writes wake the cars' long polls held on the other threads."""
    return AssignmentSignals()


def league_service(settings: Settings | None = None) -> LeagueService:
    """Boards are kept per process for a second (domain/league_board_cache.py); a write through it drops them."""
    from chalicelib.domain.league_board_cache import PROCESS_LEAGUE_BOARDS

    settings = settings or get_settings()
    return LeagueService(DynamoLeagueStore(clients.dynamodb(), settings.table("league")),
                         boards=PROCESS_LEAGUE_BOARDS)


def league_verify_queue(settings: Settings | None = None) -> ScrutineerQueue | None:
    """drem's re-drives of league models, where a worker can drive them (as for scrutineering); None elsewhere, and
    a push that brings its model is told the server cannot re-drive it."""
    settings = settings or get_settings()
    if importlib.util.find_spec("drem_sim") is None and not settings.scrutineering_worker:
        return None
    return ScrutineerQueue(DynamoJobStore(clients.dynamodb(), settings.table("league"), queue_pk=LEAGUE_QUEUE_PK),
                           now_ms)


def league_intake(settings: Settings | None = None) -> LeagueIntake:
    settings = settings or get_settings()
    queue = league_verify_queue(settings)
    return LeagueIntake(league_service(settings), scrutineer_service(settings) if queue else None, queue)


# --- the racer queue (on deck) --------------------------------------------------------------------------------------

class RacersModels:
    """The queue's model lookup: a racer's AVAILABLE models (the ones a car may be given)."""

    def __init__(self, models: ModelService) -> None:
        self._models = models

    def available_models_of(self, owner_sub: str) -> list[ModelRecord]:
        found, token = [], None
        while True:
            page = self._models.store.list_owner(owner_sub, limit=100, next_token=token)
            found += [m for m in page.models if m.status is ModelStatus.AVAILABLE and m.s3_key is not None]
            token = page.next_token
            if not token:
                return found


def racer_queue_service() -> RacerQueueService:
    return RacerQueueService(DynamoQueueStore(clients.dynamodb(), get_settings().table("races")), race_service(),
                             user_directory(), RacersModels(model_service()), now_ms)


def on_deck() -> OnDeck:
    return OnDeck(racer_queue_service(), race_service(), race_store(), device_service(), assignment_service())


# --- the learning booth ---------------------------------------------------------------------------------------------

# Live manual drives are held by the app process (chalicelib.domain.booth_drive): one table for the process.
LIVE_DRIVES = LiveDrives()


def track_service() -> TrackService:
    return TrackService()


def run_service(settings: Settings | None = None) -> RunService:
    settings = settings or get_settings()
    files = S3ModelFiles(clients.s3(), settings.bucket("runs"), clients.s3_presigner())
    return RunService(DynamoBoothStore(clients.dynamodb(), settings.table("booth")), files, track_service(),
                      model_service(settings))


def training_service(settings: Settings | None = None) -> TrainingService:
    settings = settings or get_settings()
    return TrainingService(DynamoBoothStore(clients.dynamodb(), settings.table("booth")), run_service(settings),
                           model_service(settings))


def drive_service() -> DriveService:
    return DriveService(LIVE_DRIVES, run_service(), get_settings().drive_dir)


class _AppSessionBackends:
    """chalicelib.auth.sessions keeps and renews sessions through these (it must not import this module)."""

    def session_store(self) -> DynamoSessionStore:
        return session_store()

    def identity_provider(self, settings: Settings) -> CognitoIdentityProvider:
        return identity_provider(settings)


use_session_backends(_AppSessionBackends())
