"""Trust on first use for a stock DeepRacer's self-signed HTTPS certificate.

Each car makes its own certificate (no CA can vouch for it), so drem pins the certificate itself: its SHA-256
fingerprint is recorded at the first contact with the car (or taken from a certificate file staff copied from the
car), kept in the agent's config directory, and every later connection must present the same certificate. A car that
presents another one is refused with a message that says so: on a venue WiFi that is someone impersonating the car,
or a car that was re-imaged (then staff give drem the new certificate with --deepracer-cert).

The pin is checked by urllib3 itself (`assert_fingerprint`) on every connection; such a connection counts as
verified, so no InsecureRequestWarning is printed.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import ssl
from pathlib import Path
from urllib.parse import urlsplit

from requests.adapters import HTTPAdapter

KNOWN_CARS_FILE = "deepracer-certificates.json"
_FINGERPRINT = re.compile(r"^(?:sha256[:=\s]*)?((?:[0-9a-f]{2}:?){32})$", re.I)


class CertificateProblem(RuntimeError):
    """The car's certificate is not the one drem trusts, or the file staff gave cannot be read."""


def fingerprint_of_der(der: bytes) -> str:
    return hashlib.sha256(der).hexdigest()


def fingerprint_of_file(path: Path) -> str:
    """A PEM certificate (as copied from the car), or a file holding its SHA-256 fingerprint in hex."""
    try:
        text = path.read_text(encoding="ascii", errors="strict").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise CertificateProblem(f"cannot read the car certificate file {path}: {exc}") from None
    match = _FINGERPRINT.match(text)
    if match:
        return match.group(1).replace(":", "").lower()
    try:
        return fingerprint_of_der(ssl.PEM_cert_to_DER_cert(text))
    except ValueError:
        raise CertificateProblem(f"{path} is neither a PEM certificate nor a SHA-256 fingerprint") from None


def car_address(url: str) -> tuple[str, int]:
    parts = urlsplit(url)
    return parts.hostname or "", parts.port or 443


def fetch_fingerprint(url: str, timeout_s: float = 10.0) -> str:
    """The fingerprint of the certificate the car presents now (OSError when the car does not answer)."""
    pem = ssl.get_server_certificate(car_address(url), timeout=timeout_s)
    return fingerprint_of_der(ssl.PEM_cert_to_DER_cert(pem))


def pretty(fingerprint: str) -> str:
    return ":".join(fingerprint[i:i + 2] for i in range(0, len(fingerprint), 2)).upper()


class CarTrust:
    """The fingerprints drem trusts, one per car address, in `<config dir>/deepracer-certificates.json`."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / KNOWN_CARS_FILE

    def known(self) -> dict[str, str]:
        try:
            data = json.loads(self.path.read_text())
        except FileNotFoundError:
            return {}
        except (OSError, ValueError) as exc:
            raise CertificateProblem(f"{self.path} cannot be read ({exc}); delete it to trust each car again at "
                                     "its next first contact") from None
        return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}

    def pin_for(self, url: str, given: Path | None = None) -> tuple[str | None, str | None]:
        """(fingerprint to require, what was done in words) for the car at `url`; (None, None) for plain http.
        Contacts the car only the first time (OSError while it does not answer)."""
        if urlsplit(url).scheme != "https":
            return None, None
        host, port = car_address(url)
        key = f"{host}:{port}"
        known = self.known()
        if given is not None:
            fingerprint = fingerprint_of_file(given)
            if known.get(key) != fingerprint:
                self._record(known, key, fingerprint)
            return fingerprint, f"trusting the certificate in {given} for {key} (sha256 {pretty(fingerprint)})"
        if key in known:
            return known[key], None
        fingerprint = fetch_fingerprint(url)
        self._record(known, key, fingerprint)
        return fingerprint, (f"first contact with the car at {key}: trusting its certificate from now on "
                             f"(sha256 {pretty(fingerprint)}, recorded in {self.path})")

    def _record(self, known: dict[str, str], key: str, fingerprint: str) -> None:
        known = {**known, key: fingerprint}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        partial = self.path.with_suffix(".partial")
        with open(partial, "w") as handle:
            json.dump(known, handle, indent=1, sort_keys=True)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(partial, self.path)


class PinnedCertificateAdapter(HTTPAdapter):
    """HTTPS to one car: no CA check (the car signs its own), the certificate's SHA-256 must match the pin."""

    def __init__(self, fingerprint: str) -> None:
        self.fingerprint = fingerprint
        super().__init__()

    def init_poolmanager(self, *args, **kwargs) -> None:
        kwargs["assert_fingerprint"] = self.fingerprint
        super().init_poolmanager(*args, **kwargs)


def changed_certificate_message(url: str, error: str) -> str:
    presented = re.search(r'got "?([0-9a-f:]{64,95})', error, re.I)
    now = f" (it now shows sha256 {pretty(presented.group(1).replace(':', '').lower())[:23]}...)" if presented else ""
    return (f"the car at {url} presents a different certificate than the one drem trusts{now}: refused. Someone "
            "may be impersonating the car on the WiFi; if staff re-imaged the car, give drem its new certificate "
            "with --deepracer-cert FILE")
