"""The pure-pursuit demonstrator laps every shipped closed track, both ways, without leaving it."""
from __future__ import annotations

import pytest

from drem_sim.demonstrator import Demonstrator
from drem_sim.env import EnvConfig, RaceEnv
from drem_sim.tracks import available_tracks, load_track

pytestmark = pytest.mark.sim

CLOSED = [name for name in sorted(available_tracks()) if load_track(name).is_closed]


def test_every_closed_shipped_track_is_covered() -> None:
    assert len(CLOSED) >= 9


@pytest.mark.parametrize("name", CLOSED)
@pytest.mark.parametrize("reverse", [False, True])
def test_demonstrator_laps_without_resets(name: str, reverse: bool) -> None:
    track = load_track(name, reverse=reverse)
    env = RaceEnv(track, EnvConfig(observe=False, max_laps=1, max_steps=int(60 * 15)))
    driver = Demonstrator(track)
    _, info = env.reset(seed=0)
    params = info["params"]
    done = False
    while not done:
        _, params, terminated, truncated, info = env.step(driver.act(params))
        done = terminated or truncated
    assert info["laps"] == 1 and info["resets"] == 0
    # A believable lap: faster than a crawl, slower than the sim's 4 m/s limit allows.
    assert track.length / 2.5 < info["lap_times_s"][0] < track.length / 1.0


def test_demonstrator_also_drives_from_a_car_state() -> None:
    env = RaceEnv("drem_oval", EnvConfig(observe=False, max_steps=150))
    driver = Demonstrator(env.track)
    env.reset(seed=3)
    for _ in range(150):  # 10 s: more than one lap of the 17 m oval
        env.step(driver.act(env.car_state()))
    assert env.resets == 0 and env.laps == 1
