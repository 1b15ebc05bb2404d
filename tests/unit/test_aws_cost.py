"""bench/aws_cost.py's request model counts what the event profile implies (not its dollar figure, which is the
bench's output): push costs grow with viewers only as delivered bytes, never as DynamoDB reads or requests per poll."""
from __future__ import annotations

import importlib.util
import sys
from dataclasses import replace
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench" / "aws_cost.py"


@pytest.fixture(scope="module")
def aws_cost():
    spec = importlib.util.spec_from_file_location("aws_cost_bench", BENCH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses resolve their annotations through sys.modules
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def sizes(aws_cost):
    return aws_cost.measure()


def test_the_measured_board_is_a_50_racer_fragment_and_each_message_is_gzipped_on_its_own(aws_cost, sizes):
    assert sizes.board_gzip < sizes.board_html / 4, "a board fragment is repetitive markup: gzip shrinks it a lot"
    assert sizes.overlay_gzip < sizes.overlay_html
    more = aws_cost.measure(racers=100)
    assert more.board_html > 1.8 * sizes.board_html, "the fragment grows with the racers, so 50 were rendered"
    assert aws_cost.gzipped(b"x" * 10_000) < 100


def test_polling_asks_once_per_poll_per_spectator(aws_cost, sizes):
    profile = aws_cost.Profile(spectators=2_000, hours=8, poll_every_s=0.5)
    base = aws_cost.non_live(profile, sizes)
    polled = aws_cost.polling(profile, sizes)

    assert polled.api_requests - base.api_requests == 2_000 * 8 * 3600 * 2  # 115.2 M, the figure
    assert polled.lambda_requests == polled.api_requests
    faster = aws_cost.polling(replace(profile, poll_every_s=0.25), sizes)
    assert faster.api_requests - base.api_requests == 2 * (polled.api_requests - base.api_requests)


def test_doubling_the_spectators_doubles_delivered_updates_but_not_the_live_servers_reads(aws_cost, sizes):
    profile = aws_cost.Profile(spectators=2_000, viewers_per_task=4_000)
    double = replace(profile, spectators=4_000)
    one, two = aws_cost.push(profile, sizes), aws_cost.push(double, sizes)

    assert aws_cost.tasks(profile) == aws_cost.tasks(double) == 1
    # Everyone but the fixed screens and overlays is a phone on a board: the phones double, the screens do not.
    assert two.delivered_updates - one.delivered_updates == 2_000 * (8 * 3600 / 2)
    assert two.live_dynamodb_reads == one.live_dynamodb_reads
    assert two.dynamodb_rru == one.dynamodb_rru
    live_bytes = [u.cloudfront_bytes_out - aws_cost.non_live(p, sizes).cloudfront_bytes_out
                  for u, p in ((one, profile), (two, double))]
    assert 1.98 < live_bytes[1] / live_bytes[0] < 2.01


def test_push_requests_do_not_follow_the_poll_rate_and_every_viewer_gets_every_lap(aws_cost, sizes):
    profile = aws_cost.Profile()
    faster = replace(profile, poll_every_s=0.1)
    assert aws_cost.push(profile, sizes).cloudfront_requests == aws_cost.push(faster, sizes).cloudfront_requests

    pushed = aws_cost.push(profile, sizes)
    laps_per_track = profile.seconds / profile.lap_every_s
    assert profile.phones + profile.screens + profile.overlays == profile.spectators
    assert pushed.delivered_updates == profile.spectators * laps_per_track
    # The server's reads: a fixed poll of every channel's two items, plus one race read per overlay version.
    polls = profile.channels * profile.seconds / profile.server_poll_every_s
    assert pushed.live_dynamodb_reads == 2 * polls + profile.tracks * laps_per_track


def test_more_viewers_than_a_task_carries_add_a_task_and_its_reads(aws_cost, sizes):
    profile = aws_cost.Profile(spectators=10_000, viewers_per_task=4_000)
    assert aws_cost.tasks(profile) == 3
    small = aws_cost.push(replace(profile, spectators=2_000), sizes)
    assert aws_cost.push(profile, sizes).live_dynamodb_reads == 3 * small.live_dynamodb_reads


def test_every_lap_pays_its_writes_whatever_the_design_and_the_crowd(aws_cost, sizes):
    profile = aws_cost.Profile()
    wru, rru = aws_cost.lap_writes(profile, sizes)
    # The race transaction (2x), the track board with its ranking state, the combined board, the overlay, the intent.
    assert wru >= 2 * 2 + sizes.board_item / 1024 + sizes.overlay_item / 1024
    assert rru > 0
    for design in (aws_cost.polling, aws_cost.push):
        assert design(profile, sizes).dynamodb_wru == profile.laps * wru
        assert design(replace(profile, spectators=20_000), sizes).dynamodb_wru == profile.laps * wru
    assert aws_cost.dollars(aws_cost.push(profile, sizes))["DynamoDB writes"] > 0


def test_the_live_server_polls_at_its_real_interval_on_aws_where_the_writer_wakes_it(aws_cost):
    from drem_live.__main__ import WOKEN_POLL_MS

    assert aws_cost.Profile().server_poll_every_s == WOKEN_POLL_MS / 1000


def test_every_write_that_changes_a_live_page_pays_its_wake_up_post(aws_cost, sizes):
    profile = aws_cost.Profile()
    silent = replace(profile, wakes_per_lap=0)
    woken, unwoken = aws_cost.push(profile, sizes), aws_cost.push(silent, sizes)
    assert woken.cloudfront_requests - unwoken.cloudfront_requests == profile.laps * 3
    assert woken.lambda_gb_seconds > unwoken.lambda_gb_seconds
    assert aws_cost.push(replace(profile, spectators=20_000), sizes).cloudfront_requests - \
        aws_cost.push(replace(silent, spectators=20_000), sizes).cloudfront_requests == profile.laps * 3
