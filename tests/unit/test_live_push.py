"""The live server's building blocks without a network: version-token order (the rule live.js applies too), a
channel that never broadcasts an older state, and gzip chunks compressed once that any subscriber can append."""
from __future__ import annotations

import asyncio
import zlib
from concurrent.futures import ThreadPoolExecutor

import pytest
from aiohttp import web

from chalicelib.security_headers import content_security_policy
from chalicelib.settings import Settings
from chalicelib.views.live_regions import token_is_newer
from drem_live.channels import Channels, Subscriber
from drem_live.limits import Limits, StreamCount
from drem_live.sse import GZIP_HEADER, HEARTBEAT, Message, accepts_gzip, event_bytes
from tests import coroutines


@pytest.mark.parametrize(("candidate", "shown", "newer"), [
    ("2.5-0", "1.5-0", True),          # the board moved on
    ("1.6-0", "1.5-2", True),          # a new race: its phase starts again at "racing"
    ("1.5-1", "1.5-0", True),          # the overlay's phase advanced (racing → just finished)
    ("1.5-0", "1.5-1", False),         # a Lambda whose cache still had the racing phase
    ("1.5-0", "2.5-0", False),         # instance A renders v0 again after B rendered v1
    ("1.5-0", "1.5-0", False),         # the same state is no news
    ("2.4-0", "1.5-0", False),         # mixed (board newer, overlay older): wait for one newer in both
    ("3.7-1.7-0", "3.7-0.7-0", True),  # a held summary ended (0 held → 1 shown)
    ("3.7-1", None, True),             # anything beats nothing
])
def test_a_token_is_newer_only_when_nothing_in_it_went_back(candidate, shown, newer) -> None:
    assert token_is_newer(candidate, shown) is newer


def _broadcasts(tokens: list[str]) -> list[str]:
    """Tokens a subscriber receives from a channel whose storage reads give `tokens` one after the other."""
    async def run() -> list[str]:
        reads = iter(tokens)
        done = asyncio.Event()
        received: list[str] = []

        def step(_last: Message | None) -> Message | None:
            token = next(reads, None)
            if token is None:
                done.set()
                return None
            return Message.fragment(token, f"<section data-version=\"{token}\"></section>")

        with ThreadPoolExecutor(1) as executor:
            channels = Channels(0.001, executor, max_channels=4, is_newer=token_is_newer)
            subscriber = Subscriber()
            channel = channels.join(("leaderboard", "e1"), step, subscriber)
            while not done.is_set():
                try:
                    await asyncio.wait_for(subscriber.wake.wait(), 0.05)
                except TimeoutError:
                    continue
                message = subscriber.take()
                if message is not None:
                    received.append(message.token)
            channels.leave(channel, subscriber)
            assert len(channels) == 0  # the last subscriber left: the channel (and its watcher) stopped
        return received

    return coroutines.run(run())


def test_a_channel_never_broadcasts_an_older_state_than_it_sent() -> None:
    received = _broadcasts(["1.5-0", "1.6-0", "1.5-0", "1.6-0", "2.6-1", "1.6-1"])
    # A slow subscriber may skip an intermediate state (it keeps only the newest), never go back.
    assert received[-1] == "2.6-1" and set(received) <= {"1.5-0", "1.6-0", "2.6-1"}, received
    assert all(token_is_newer(b, a) for a, b in zip(received, received[1:], strict=False)), received


def test_a_channel_cap_refuses_one_more_option_set() -> None:
    async def run() -> None:
        with ThreadPoolExecutor(1) as executor:
            channels = Channels(10, executor, max_channels=1, is_newer=token_is_newer)
            channels.join("a", lambda _last: None, Subscriber())
            with pytest.raises(Exception, match="already watches 1 different pages"):
                channels.join("b", lambda _last: None, Subscriber())
            channels.stop_all()

    coroutines.run(run())


def test_each_message_is_compressed_once_and_decodes_after_any_subscribers_header() -> None:
    first = Message.fragment("1.1-0", "<section>\nfirst</section>")
    second = Message.fragment("1.2-0", "<section>second</section>")
    # One subscriber saw both messages, one joined for the second only; both decode what they were sent.
    for chunks, expected in (([first, HEARTBEAT, second], first.plain + HEARTBEAT.plain + second.plain),
                             ([second], second.plain)):
        stream = GZIP_HEADER + b"".join(m.gzip for m in chunks)
        assert zlib.decompressobj(16 + zlib.MAX_WBITS).decompress(stream) == expected
    assert first.plain == b"id: 1.1-0\nevent: fragment\ndata: <section>\ndata: first</section>\n\n"


def test_sse_data_lines_cannot_be_ended_early_by_a_carriage_return() -> None:
    assert event_bytes("fragment", "a\rid: 9\r\nb") == b"event: fragment\ndata: a\ndata: id: 9\ndata: b\n\n"


def test_gzip_is_used_only_when_the_client_accepts_it() -> None:
    assert accepts_gzip("gzip, deflate, br") and accepts_gzip("br;q=1, gzip;q=0.5")
    assert not accepts_gzip("") and not accepts_gzip("gzip;q=0") and not accepts_gzip("gzip;q=x")


def test_streams_are_capped_in_total_and_per_client_address() -> None:
    count = StreamCount(Limits(max_streams=3, max_streams_per_client=2))
    count.open("10.0.0.5")
    count.open("10.0.0.5")
    assert "from one address" in (count.refusal("10.0.0.5") or "")
    assert count.refusal("10.0.0.6") is None
    count.open("10.0.0.6")
    assert "full" in (count.refusal("10.0.0.7") or "")
    count.close("10.0.0.5")
    assert count.refusal("10.0.0.5") is None


def test_the_pages_may_connect_to_the_live_server_and_only_to_a_real_http_origin() -> None:
    local = {"AWS_ENDPOINT_URL": "http://127.0.0.1:8001", "DREM_PUBLIC_URL": "http://192.168.8.20:8000"}
    pushed = Settings.from_env({**local, "DREM_LIVE_URL": "http://192.168.8.20:8002/"})
    assert pushed.live_stream_base == "http://192.168.8.20:8002"
    assert "http://192.168.8.20:8002" in content_security_policy(pushed, embeddable=True).split("; ")[4]
    assert Settings.from_env(local).live_stream_base is None  # locally without a live server the pages poll
    assert Settings.from_env({}).live_stream_base == ""  # on AWS: /live/... on the pages' own origin
    for hostile in ("javascript:alert(1)", "http://x; script-src *", "ftp://host"):
        settings = Settings.from_env({**local, "DREM_LIVE_URL": hostile})
        assert settings.live_url is None and settings.live_stream_base is None


@pytest.mark.parametrize(("header", "value", "counted_as"), [
    ("CloudFront-Viewer-Address", "203.0.113.7:51514", "203.0.113.7"),
    ("CloudFront-Viewer-Address", "2001:db8::1:443", "2001:db8::1"),
    ("X-Forwarded-For", "198.51.100.2", "198.51.100.2"),
    ("X-Forwarded-For", "10.9.9.9, 2001:db8::5", "2001:db8::5"),  # the entry the nearest proxy added
    ("X-Forwarded-For", "", "127.0.0.1"),  # no header: the connection's own address
])
def test_behind_a_proxy_viewers_are_counted_by_the_address_it_names(header, value, counted_as) -> None:
    from aiohttp.test_utils import make_mocked_request

    from drem_live.server import STREAMS, client_address

    app = web.Application()
    app[STREAMS] = StreamCount(Limits(client_address_header=header))
    request = make_mocked_request("GET", "/live/leaderboard/e1", headers={header: value} if value else {}, app=app,
                                  transport=_Transport("127.0.0.1"))
    assert client_address(request) == counted_as


class _Transport:
    def __init__(self, peer: str) -> None:
        self.peer = peer

    def get_extra_info(self, name: str, default: object = None) -> object:
        return (self.peer, 40000) if name == "peername" else default


def test_a_crowd_behind_one_address_is_not_capped_by_default() -> None:
    """Issue 27: behind a venue's NAT every phone is one address; 64 streams per address turned spectators away."""
    count = StreamCount(Limits(max_streams=5000))
    board = ("leaderboard", "e1", "1")
    for _ in range(1000):
        assert count.refusal("203.0.113.7", board, 1) is None
        count.open("203.0.113.7", board)
    assert count.total == 1000


def test_near_full_a_flooded_page_gets_no_more_than_its_fair_share() -> None:
    """An attacker's 70 streams on one page cannot crowd out the spectators of another once the server is nearly
    full: past 80% of the cap, a new stream goes only to a page under its share (cap / open pages)."""
    count = StreamCount(Limits(max_streams=100))
    flooded, board = ("overlay", "e1", "x"), ("leaderboard", "e1", "1")
    for _ in range(70):
        count.open("10.0.0.66", flooded)
    for _ in range(10):
        count.open("10.0.0.66", board)

    assert "its share (50 viewers)" in (count.refusal("10.0.0.66", flooded, 2) or "")
    assert count.refusal("10.0.0.66", board, 2) is None  # the spectators' page still admits
    for _ in range(20):
        count.open("10.0.0.66", board)
    assert "full (100 viewers)" in (count.refusal("10.0.0.66", board, 2) or "")  # at the cap, all are shed alike


def test_made_up_option_sets_of_one_page_cannot_take_every_channel() -> None:
    """Issue 27: 4 addresses x 64 distinct query strings took all 256 channels; now one page holds at most its
    per-page number of option sets, other pages still open, and joining an open option set is always free."""
    async def run() -> None:
        with ThreadPoolExecutor(1) as executor:
            channels = Channels(10, executor, max_channels=256, is_newer=token_is_newer, max_per_page=16)
            page = ("overlay", "e1")
            for n in range(16):
                channels.join(("overlay", "e1", n), lambda _last: None, Subscriber(), page=page)
            with pytest.raises(Exception, match="already watched with 16 options of its own"):
                channels.join(("overlay", "e1", "made-up"), lambda _last: None, Subscriber(), page=page)
            channels.join(("overlay", "e1", 3), lambda _last: None, Subscriber(), page=page)  # already open: joins
            channels.join(("leaderboard", "e1", "1"), lambda _last: None, Subscriber(), page=("leaderboard", "e1"))
            # An overlay the console's link builder made still gets its channel: the 16 slots are for other options.
            channels.join(("overlay", "e1", "offered"), lambda _last: None, Subscriber(), page=page, offered=True)
            assert len(channels) == 18
            channels.stop_all()

    coroutines.run(run())


def test_a_wake_reads_the_events_channels_at_once_and_no_others() -> None:
    """With a poll of an hour, only a wake-up makes a channel read again; a wake for another event reads nothing."""
    async def run() -> tuple[int, int, int]:
        reads = {"e1": 0, "e2": 0}

        def step_for(event_id: str):
            def step(_last: Message | None) -> Message | None:
                reads[event_id] += 1
                return Message.fragment(f"{reads[event_id]}.0-0", "<section></section>")
            return step

        with ThreadPoolExecutor(1) as executor:
            channels = Channels(3600, executor, max_channels=4, is_newer=token_is_newer)
            first, second = Subscriber(), Subscriber()
            channels.join(("overlay", "e1"), step_for("e1"), first, event_id="e1")
            channels.join(("overlay", "e2"), step_for("e2"), second, event_id="e2")
            await asyncio.wait_for(first.wake.wait(), 10)
            await asyncio.wait_for(second.wake.wait(), 10)
            first.take(), second.take()
            assert channels.wake("e1") == 1
            await asyncio.wait_for(first.wake.wait(), 10)  # the poll would come in an hour
            woken = first.take()
            assert woken is not None and woken.token == "2.0-0"
            assert channels.wake("nobody") == 0
            channels.stop_all()
            return reads["e1"], reads["e2"], len(channels)

    assert coroutines.run(run()) == (2, 1, 0)


def test_the_streams_metric_is_one_embedded_metric_format_record() -> None:
    import json

    from drem_live.metrics import emf_line

    record = json.loads(emf_line("drem/live", "prod", 1234, 1_800_000_000_000))
    [directive] = record["_aws"]["CloudWatchMetrics"]
    assert directive == {"Namespace": "drem/live", "Dimensions": [["Stage"]],
                         "Metrics": [{"Name": "Streams", "Unit": "Count"}]}
    assert (record["Stage"], record["Streams"], record["_aws"]["Timestamp"]) == ("prod", 1234, 1_800_000_000_000)


def test_a_wake_makes_the_next_json_poll_read_again() -> None:
    from drem_live.polls import PollViews

    async def run() -> list[int]:
        versions = iter([1, 2])
        with ThreadPoolExecutor(1) as executor:
            polls = PollViews(lambda _k, _e, _t: (next(versions), "{}"), 3600, executor)
            seen = [(await polls.get("leaderboard", "e1", "1")).version,
                    (await polls.get("leaderboard", "e1", "1")).version]  # within the hour: from memory
            polls.expire("e2")
            seen.append((await polls.get("leaderboard", "e1", "1")).version)  # another event's wake-up
            polls.expire("e1")
            seen.append((await polls.get("leaderboard", "e1", "1")).version)
            return seen

    assert coroutines.run(run()) == [1, 1, 1, 2]


def test_hand_made_option_sets_of_many_pages_leave_half_the_channels_to_the_pages_drem_offers() -> None:
    async def run() -> None:
        with ThreadPoolExecutor(1) as executor:
            channels = Channels(10, executor, max_channels=8, is_newer=token_is_newer, max_per_page=16)
            for n in range(4):
                channels.join(("overlay", f"e{n}", "made-up"), lambda _last: None, Subscriber(),
                              page=("overlay", f"e{n}"))
            with pytest.raises(Exception, match="4 pages with options of their own"):
                channels.join(("overlay", "e9", "made-up"), lambda _last: None, Subscriber(), page=("overlay", "e9"))
            for n in range(4):
                channels.join(("overlay", "e9", n), lambda _last: None, Subscriber(), page=("overlay", "e9"),
                              offered=True)
            assert len(channels) == 8
            channels.stop_all()

    coroutines.run(run())


def test_one_timer_beats_every_idle_viewer_and_never_replaces_a_pending_board() -> None:
    async def run() -> None:
        with ThreadPoolExecutor(1) as executor:
            channels = Channels(10, executor, max_channels=8, is_newer=token_is_newer)
            idle, busy = Subscriber(), Subscriber()
            channels.join("board", lambda _last: None, idle)
            channels.join("board", lambda _last: None, busy)
            board = Message.fragment("1.1-0", "<section>board</section>")
            busy.offer(board)
            beating = asyncio.get_running_loop().create_task(channels.beat_every(0.01))
            await asyncio.wait_for(idle.wake.wait(), 5)
            beating.cancel()
            assert idle.heartbeat_due and idle.take() is None  # a heartbeat, nothing else
            assert not busy.heartbeat_due and busy.take() == board  # its board is still what it gets
            channels.stop_all()

    coroutines.run(run())


def test_while_a_timed_re_read_is_in_flight_other_polls_get_the_last_view_at_once_but_after_a_wake_they_wait(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import threading
    import types

    from drem_live import polls as polls_module
    from drem_live.polls import PollViews

    clock = [1000.0]
    monkeypatch.setattr(polls_module, "time", types.SimpleNamespace(monotonic=lambda: clock[0]))

    async def run() -> tuple[int | None, int, int | None]:
        release = threading.Event()
        versions = iter([1, 2, 3])

        def read(_k: str, _e: str, _t: str) -> tuple[int, str]:
            version = next(versions)
            if version > 1:
                assert release.wait(10), "the test never let the read finish"
            return version, "{}"

        with ThreadPoolExecutor(1) as executor:
            polls = PollViews(read, 0.25, executor)
            await polls.get("leaderboard", "e1", "1")
            clock[0] += 0.3  # the view is now past its freshness
            first = asyncio.ensure_future(polls.get("leaderboard", "e1", "1"))  # starts the re-read, waits for it
            await asyncio.sleep(0)
            during = polls.fresh("leaderboard", "e1", "1")  # another poll meanwhile: answered from memory
            release.set()
            after_read = (await first).version
            release.clear()
            polls.expire("e1")
            woken = asyncio.ensure_future(polls.get("leaderboard", "e1", "1"))
            await asyncio.sleep(0)
            during_wake = polls.fresh("leaderboard", "e1", "1")  # news: nobody gets the old view
            release.set()
            await woken
            return (during.version if during else None), after_read, (during_wake.version if during_wake else None)

    assert coroutines.run(run()) == (1, 2, None)
