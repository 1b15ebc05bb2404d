"""On AWS without a custom domain the functions read their public URL from the stack's SSM parameter (written by
every deploy from the CloudFront distribution), so no deploy serves the local fallback URL: links, QR codes and Secure
cookies are right from the first request. A failed read fails that request instead of serving 127.0.0.1."""
from __future__ import annotations

import pytest

from drem_local.bootstrap import StackOutputs

pytestmark = pytest.mark.unit

PARAMETER = "/drem/test/public-url"
CLOUDFRONT_URL = "https://d111111abcdef8.cloudfront.net"


@pytest.fixture
def no_url_in_the_environment(stack: StackOutputs, monkeypatch: pytest.MonkeyPatch) -> None:
    from chalicelib.settings import get_settings

    monkeypatch.setenv("DREM_PUBLIC_URL_PARAMETER", PARAMETER)
    monkeypatch.delenv("DREM_PUBLIC_URL", raising=False)
    get_settings.cache_clear()


def _put(value: str) -> None:
    """What the stack's AWS::SSM::Parameter holds after a deploy (written here as CloudFormation would)."""
    import boto3

    boto3.client("ssm", region_name="us-east-1").put_parameter(Name=PARAMETER, Value=value, Type="String",
                                                              Overwrite=True)


def test_the_public_url_comes_from_the_stacks_parameter(no_url_in_the_environment: None, desk) -> None:
    from chalicelib import services  # noqa: F401  (the composition root installs the parameter reader)
    from chalicelib.settings import get_settings

    _put(CLOUDFRONT_URL)
    get_settings.cache_clear()
    settings = get_settings()
    assert settings.public_url == CLOUDFRONT_URL and settings.cookie_secure
    page = desk.anonymous_get("/login")
    assert page.status_code == 200
    cookies = page.headers.get("Set-Cookie", [])
    cookies = [cookies] if isinstance(cookies, str) else cookies
    assert "127.0.0.1" not in page.body.decode()
    assert cookies and all("Secure" in cookie for cookie in cookies), cookies


def test_a_missing_parameter_fails_the_request_and_the_next_read_succeeds(no_url_in_the_environment: None) -> None:
    from chalicelib import services  # noqa: F401
    from chalicelib.core.errors import DremError
    from chalicelib.settings import get_settings

    with pytest.raises(DremError):
        get_settings()  # not the 127.0.0.1 fallback
    _put(CLOUDFRONT_URL)
    assert get_settings().public_url == CLOUDFRONT_URL
