"""Where `drem up` serves the app and what URL it announces; storage stays on loopback whatever the flags."""
from __future__ import annotations

from pathlib import Path

import pytest

from drem_local.stack import StackConfig, StackError, lan_address, lan_config

pytestmark = pytest.mark.unit


def test_without_flags_everything_is_on_loopback():
    config = StackConfig(state_dir=Path("s"), app_port=8000, storage_port=8001)
    assert (config.app_host, config.app_url, config.storage_url) == (
        "127.0.0.1", "http://127.0.0.1:8000", "http://127.0.0.1:8001")


def test_lan_on_every_interface_announces_the_default_route_address_and_keeps_storage_local():
    try:
        address = lan_address()
    except StackError as exc:  # a machine with no network: then --lan says what to do instead
        assert "--host ADDR" in str(exc)
        with pytest.raises(StackError):
            lan_config(StackConfig(state_dir=Path("s")), None)
        return
    config = lan_config(StackConfig(state_dir=Path("s"), app_port=8000, storage_port=8001), None)

    assert not address.startswith("127.")
    assert config.app_host == "0.0.0.0" and config.app_url == f"http://{address}:8000"
    assert config.app_local_url == "http://127.0.0.1:8000"
    assert config.storage_url == "http://127.0.0.1:8001"


def test_a_named_address_is_bound_and_announced_and_must_belong_to_this_machine():
    config = lan_config(StackConfig(state_dir=Path("s"), app_port=8000), "127.0.0.1")
    assert config.app_url == "http://127.0.0.1:8000"
    with pytest.raises(StackError, match="not an IPv4 address of this machine"):
        lan_config(StackConfig(state_dir=Path("s")), "203.0.113.9")


def test_a_tls_proxy_url_is_what_people_get():
    config = lan_config(StackConfig(state_dir=Path("s"), app_port=8000), None, "https://drem.example.org/")
    assert config.app_url == "https://drem.example.org" and config.app_host == "0.0.0.0"


def test_test_servers_get_ports_no_outgoing_connection_can_hold():
    # A durable server restarted on its port once found it held by another test's client connection: the kernel puts
    # the local end of outgoing connections in its ephemeral range, so free_port draws below it, and the port binds.
    import socket

    from drem_local.stack import _ephemeral_ports, free_port

    low, _ = _ephemeral_ports()
    with socket.create_server(("127.0.0.1", 0)) as listener, \
            socket.create_connection(listener.getsockname()) as client:
        assert client.getsockname()[1] >= low  # where outgoing connections live
        ports = [free_port() for _ in range(50)]
    assert all(1024 <= port < low for port in ports)
    with socket.create_server(("127.0.0.1", ports[0])):
        pass
