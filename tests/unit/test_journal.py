"""The write-ahead journal keeps every intact record and cuts off a torn tail so later appends are not lost."""
from __future__ import annotations

import pytest

from drem_local.durable.journal import SEGMENT_BYTES, Journal, JournalRecord, read_all

pytestmark = pytest.mark.unit


def _record(seq: int, body: bytes = b"{}") -> JournalRecord:
    return JournalRecord(seq, "dynamodb", {"REQUEST_METHOD": "POST", "PATH_INFO": "/"}, body)


def _write(path, records, *, fsync=False) -> Journal:
    journal = Journal(path, fsync=fsync)
    journal.open()
    for record in records:
        journal.append(record)
    return journal


def _damage(path, start: int, end: int, byte: int = 0) -> None:
    data = bytearray(path.read_bytes())
    data[start:end] = bytes([byte]) * (end - start)
    path.write_bytes(bytes(data))


def test_records_come_back_in_order_with_their_bodies(tmp_path):
    path = tmp_path / "journal.bin"
    _write(path, [_record(1, b"first"), _record(2, b"second"), _record(3, b"\x07" * 70_000)]).close()

    result = read_all(path)

    assert [(r.seq, r.body[:6]) for r in result.records] == [(1, b"first"), (2, b"second"), (3, b"\x07" * 6)]
    assert result.torn_bytes == 0


@pytest.mark.parametrize("lost", [1, 5, 9, 20, "all-but-header"])
def test_a_torn_last_record_is_dropped_and_cut_off_so_new_appends_survive(tmp_path, lost):
    path = tmp_path / "journal.bin"
    journal = _write(path, [_record(1)])
    end_of_first = journal.bytes
    journal.append(_record(2, b"x" * 100))
    end_of_second = journal.bytes
    journal.close()
    # The crash hit while record 2 was being written: its last bytes never reached the disk.
    cut = end_of_second - end_of_first - 8 if lost == "all-but-header" else lost
    _damage(path, end_of_second - cut, end_of_second, byte=0)

    journal = Journal(path, fsync=True)
    recovered = journal.open()
    assert [r.seq for r in recovered.records] == [1]
    assert recovered.torn_bytes > 0
    journal.append(_record(3, b"after the crash"))
    journal.close()

    assert [(r.seq, r.body) for r in read_all(path).records] == [(1, b"{}"), (3, b"after the crash")]


def test_a_corrupt_record_ends_the_journal_even_if_its_length_fits(tmp_path):
    path = tmp_path / "journal.bin"
    journal = _write(path, [_record(1), _record(2, b"payload-two")])
    end = journal.bytes
    journal.close()
    _damage(path, end - 3, end - 2, byte=0xFF)  # a flipped byte inside record 2: its checksum no longer matches

    assert [r.seq for r in read_all(path).records] == [1]


def test_emptying_hides_old_records_even_where_new_ones_do_not_overwrite_them(tmp_path):
    path = tmp_path / "journal.bin"
    journal = _write(path, [_record(1), _record(2), _record(3, b"long" * 100)], fsync=True)
    assert journal.records == 3

    journal.truncate()
    assert (journal.records, journal.bytes) == (0, 0)
    assert read_all(path).records == []
    journal.append(_record(4))  # overwrites record 1 exactly; records 2 and 3 still sit on disk behind it
    journal.close()

    assert [r.seq for r in read_all(path).records] == [4]


def test_the_file_grows_in_zeroed_segments_for_records_larger_than_one(tmp_path):
    path = tmp_path / "journal.bin"
    big = b"\x01" * (SEGMENT_BYTES + 10)
    _write(path, [_record(1), _record(2, big), _record(3)]).close()

    assert path.stat().st_size % SEGMENT_BYTES == 0
    assert [len(r.body) for r in read_all(path).records] == [2, len(big), 2]


def test_after_emptying_shorter_new_records_do_not_look_like_a_torn_tail(tmp_path, caplog):
    """New records end in the middle of a longer record of the previous cycle: recovery must see a clean end (no
    'torn tail' of leftovers) and appends after recovery must survive."""
    path = tmp_path / "journal.bin"
    journal = _write(path, [_record(1, b"a" * 5000), _record(2, b"b" * 5000)], fsync=True)
    journal.truncate()
    journal.append(_record(3, b"c" * 700))  # ends inside old record 1
    journal.append(_record(4, b"d" * 900))
    journal.close()

    with caplog.at_level("WARNING", logger="drem.durable"):
        reopened = Journal(path, fsync=True)
        recovered = reopened.open()
    assert [r.seq for r in recovered.records] == [3, 4]
    assert recovered.torn_bytes == 0 and "partly written" not in caplog.text
    reopened.append(_record(5))
    reopened.close()
    assert [r.seq for r in read_all(path).records] == [3, 4, 5]
