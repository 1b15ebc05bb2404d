"""Reaching a stock car at an event: waiting for a car that is not up yet, and trusting its self-signed certificate
on first use (tests/cars/fake_deepracer_console.py served over HTTPS, as the car serves it)."""
from __future__ import annotations

import signal
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import pytest

from drem_cars.car_tls import CarTrust, CertificateProblem, fingerprint_of_file, pretty
from drem_cars.credentials import CredentialStore, StoredCredential
from drem_cars.drivers.deepracer_console import ConsoleError, DeepRacerConsole
from drem_local.stack import free_port
from tests import user_processes
from tests.cars.fake_deepracer_console import FakeConsole
from tests.cars.self_signed import self_signed, server_context
from tests.waiting import wait_until

pytestmark = pytest.mark.unit


def battery_polls(fake: FakeConsole) -> int:
    return sum(1 for _method, path, _ in fake.state.calls if path == "/api/get_battery_level")


def test_first_contact_pins_the_cars_certificate_and_a_changed_one_is_refused(tmp_path: Path) -> None:
    first = server_context(*self_signed(tmp_path / "first"))
    with FakeConsole(tls=first) as fake:
        trust = CarTrust(tmp_path / "config")
        fingerprint, said = trust.pin_for(fake.url)
        assert said is not None and "first contact" in said and fingerprint is not None
        assert fingerprint == fingerprint_of_file(tmp_path / "first" / "deepracer.crt")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            console = DeepRacerConsole(fake.url, "car-password", fingerprint=fingerprint)
            for _ in range(3):
                assert console.battery_level() == 7
        assert [str(w.message) for w in caught] == [], "a pinned car is a verified connection: no warning spam"
        assert trust.pin_for(fake.url) == (fingerprint, None), "later runs use the recorded pin, silently"
        fake.restart(tls=server_context(*self_signed(tmp_path / "impostor")))
        with pytest.raises(ConsoleError, match="presents a different certificate than the one drem trusts"):
            console.battery_level()
        with pytest.raises(ConsoleError, match="different certificate"):
            DeepRacerConsole(fake.url, "car-password", fingerprint=trust.pin_for(fake.url)[0]).login()


def test_a_certificate_staff_give_is_trusted_instead_of_the_first_contact(tmp_path: Path) -> None:
    cert, key = self_signed(tmp_path / "car")
    with FakeConsole(tls=server_context(cert, key)) as fake:
        trust = CarTrust(tmp_path / "config")
        fingerprint_file = tmp_path / "fingerprint.txt"
        fingerprint_file.write_text(f"sha256 {pretty(fingerprint_of_file(cert))}\n")
        for given in (cert, fingerprint_file):
            fingerprint, said = trust.pin_for(fake.url, given)
            assert said is not None and str(given) in said
            DeepRacerConsole(fake.url, "car-password", fingerprint=fingerprint).login()
        other, _ = self_signed(tmp_path / "other")
        with pytest.raises(ConsoleError, match="different certificate"):
            DeepRacerConsole(fake.url, "car-password", fingerprint=trust.pin_for(fake.url, other)[0]).login()
        (tmp_path / "junk.txt").write_text("not a certificate")
        with pytest.raises(CertificateProblem, match="neither a PEM certificate nor a SHA-256 fingerprint"):
            trust.pin_for(fake.url, tmp_path / "junk.txt")


def test_https_to_a_car_without_a_pin_is_refused() -> None:
    with pytest.raises(ConsoleError, match="only with its certificate pinned"):
        DeepRacerConsole("https://192.168.1.20", "pw")


class RunningAgent:
    """`drem car run --deepracer` as a user runs it: the installed entry point, from outside the repository; its
    stderr read line by line as it comes."""

    def __init__(self, tmp_path: Path, url: str) -> None:
        config = tmp_path / "config"
        if not (config / "credential.json").exists():
            CredentialStore(config).save(StoredCredential(api="http://127.0.0.1:9", device_id="car-1",
                                                          device_kind="car", hostname="deepracer-07", fleet_id="f",
                                                          credential="car-1.secret"))
        drem = str(Path(sys.executable).with_name("drem"))
        self.process = subprocess.Popen(
            [drem, "car", "--config-dir", str(config), "run", "--deepracer", url, "--seconds", "120"],
            cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
            env={"PATH": "/usr/bin:/bin", "DEEPRACER_PASSWORD": "car-password", "DREM_CAR_NO_REEXEC": "1"},
            preexec_fn=user_processes.from_a_shell)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            self.lines.append(line.rstrip("\n"))

    def said(self, text: str) -> bool:
        return any(text in line for line in list(self.lines))

    def stop(self) -> int:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)  # Ctrl-C, as a user stops it
        try:
            code = self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            pytest.fail(f"drem car run did not stop on Ctrl-C within 30 s: {user_processes.state(self.process.pid)}")
        finally:
            if self.process.poll() is None:
                self.process.kill()
                self.process.wait()
        self._reader.join(10)
        return code


def test_the_installed_agent_waits_for_a_car_that_is_not_up_yet_then_drives_it(tmp_path: Path) -> None:
    port = free_port()
    url = f"https://127.0.0.1:{port}"
    tls = server_context(*self_signed(tmp_path / "car"))
    agent = RunningAgent(tmp_path, url)
    try:
        wait_until(lambda: agent.said("waiting for the DeepRacer console at") or agent.process.poll() is not None,
                   60, "the agent says where it waits")
        assert agent.process.poll() is None, agent.lines
        assert agent.said(f"waiting for the DeepRacer console at {url}")
        with FakeConsole(port=port, tls=tls) as fake:  # the car comes up after the laptop
            wait_until(lambda: battery_polls(fake) >= 2 or agent.process.poll() is not None, 90,
                       "the agent reaches the car and its heartbeat reads the battery")
            assert agent.process.poll() is None, agent.lines
            code = agent.stop()
    finally:
        agent.stop()
    assert code == 0, agent.lines
    assert sum("waiting for the DeepRacer console" in line for line in agent.lines) == 1, "one line, not one a try"
    assert agent.said("first contact with the car at 127.0.0.1") and agent.said("answers: driving it")
    assert not agent.said("InsecureRequestWarning") and not agent.said("Traceback"), agent.lines

    # The same address later shows another certificate: refused, with the reason, whoever answers there.
    with FakeConsole(port=port, tls=server_context(*self_signed(tmp_path / "impostor"))) as impostor:
        again = RunningAgent(tmp_path, url)
        code = again.process.wait(timeout=90)
        again.stop()
        assert code == 1, again.lines
        assert again.said("presents a different certificate than the one drem trusts"), again.lines
        assert not any(path == "/login" and method == "POST" for method, path, _ in impostor.state.calls), \
            "the password is never sent to a car drem does not trust"
