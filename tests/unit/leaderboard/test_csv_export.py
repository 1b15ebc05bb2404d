"""CSV exports: DREM's columns, readable by the csv module, and no formulas smuggled in through usernames."""
from __future__ import annotations

import csv
import io

import pytest

from drem_leaderboard.csv_export import ALL_LAPS_COLUMNS, RACER_SUMMARY_COLUMNS, all_laps_csv, racer_summary_csv
from drem_leaderboard.summary import summarise_racer

from .builders import submitted_race

pytestmark = pytest.mark.unit


def _rows(text: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(text)))


def test_all_laps_has_one_row_per_lap_with_drems_columns():
    race = submitted_race([10_250, 30_000], valid=[True, False], resets=[0, 5], raced_by_proxy=True)

    text = all_laps_csv([race])
    rows = _rows(text)

    assert text.splitlines()[0].split(",") == list(ALL_LAPS_COLUMNS)
    assert [r["Lap #"] for r in rows] == ["1", "2"]
    assert rows[0] == {
        "Race ID": "race-1",
        "Username": "alice",
        "User ID": "sub-alice",
        "Track": "1",
        "Raced By Proxy": "true",
        "Race Date": rows[0]["Race Date"],
        "Lap #": "1",
        "Lap Time (ms)": "10250",
        "Lap Time (s)": "10.250",
        "Resets": "0",
        "Valid": "true",
    }
    assert rows[0]["Race Date"].startswith("2023-11-14T22:1") and rows[0]["Race Date"].endswith("Z")
    assert (rows[1]["Resets"], rows[1]["Valid"]) == ("5", "false")


def test_racer_summary_has_one_row_per_racer_and_track():
    summaries = [
        summarise_racer([submitted_race([10_000, 12_000, 40_000], valid=[True, True, False], resets=[1, 0, 3])]),
        summarise_racer([submitted_race([9_000], valid=[False], sub="sub-bob", username="bob")]),
    ]

    text = racer_summary_csv(summaries)
    rows = _rows(text)

    assert text.splitlines()[0].split(",") == list(RACER_SUMMARY_COLUMNS)
    alice, bob = rows
    assert [alice[k] for k in ("Races", "Total laps", "Valid laps", "Invalid laps", "Fastest", "Avg", "Total resets",
                               "Completion %")] == [
        "1", "3", "2", "1", "10.000", "11.000", "4", "66.7",
    ]  # fmt: skip
    assert (bob["Fastest"], bob["Avg"], bob["Completion %"]) == ("", "", "0.0")


@pytest.mark.parametrize("name", ["=HYPERLINK(\"http://x\")", "+1+1", "-2+3", "@SUM(A1)", "\tcmd"])
def test_user_text_cannot_become_a_spreadsheet_formula(name):
    race = submitted_race([10_000], username=name, sub=name, track_id=name)

    lap_row = _rows(all_laps_csv([race]))[0]
    summary_row = _rows(racer_summary_csv([summarise_racer([race])]))[0]

    for cell in (lap_row["Username"], lap_row["User ID"], lap_row["Track"], summary_row["Username"]):
        assert cell == "'" + name


def test_commas_and_quotes_in_names_stay_inside_their_cell():
    race = submitted_race([10_000], username='Smith, "Speedy"')

    assert _rows(all_laps_csv([race]))[0]["Username"] == 'Smith, "Speedy"'
