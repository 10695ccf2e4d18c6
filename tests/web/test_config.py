"""The http section: listen address and the token a non-local bind needs."""

from __future__ import annotations

import pytest

from stationd.errors import ConfigError
from stationd.web.config import HttpConfig, check_http, open_bind_problem, split_listen
from stationd.yamlio import YamlNode


def read(text: str) -> HttpConfig:
    return HttpConfig.from_node(YamlNode.parse(text))


def test_defaults_and_reading():
    assert read("{}") == HttpConfig("127.0.0.1:8080", None)
    cfg = read("listen: 0.0.0.0:9000\ntoken: s3cret-token-of-the-line\n")
    assert (cfg.host, cfg.port, cfg.token) == ("0.0.0.0", 9000,  # noqa: S104
                                               "s3cret-token-of-the-line")
    assert split_listen("[::1]:8080") == ("::1", 8080)


@pytest.mark.parametrize("listen", ["0.0.0.0:8080", "192.168.1.20:80", "station.local:8080"])
def test_open_bind_without_token_is_refused(listen):
    assert "needs a token" in (open_bind_problem(HttpConfig(listen)) or "")
    with pytest.raises(ConfigError, match="needs a token"):
        check_http(HttpConfig(listen))
    with pytest.raises(ConfigError, match="<string>:1: "):
        read(f"listen: {listen}\n")


@pytest.mark.parametrize("listen", ["127.0.0.1:8080", "localhost:1", "[::1]:8080"])
def test_local_bind_needs_no_token(listen):
    assert open_bind_problem(HttpConfig(listen)) is None


@pytest.mark.parametrize("text, msg", [("listen: nowhere\n", "host:port"),
                                        ("listen: 127.0.0.1:99999\n", "0-65535"),
                                        ("listen: '999.1.1.1:80'\n",
                                         "not an IP address or a host name"),
                                        ("listen: 'a b:80'\n", "not an IP address"),
                                        ("listen: '[::zz]:80'\n", "not an IP address"),
                                        ("token: short\n", "8 characters"),
                                        ("port: 80\n", "port")])
def test_bad_section_is_one_readable_error(text, msg):
    with pytest.raises(ConfigError, match=msg):
        read(text)


@pytest.mark.parametrize("token", ["'12345678'", "change-me-to-a-long-secret"])
def test_a_short_or_example_token_is_refused_for_a_non_local_bind(token):
    """The example's placeholder and a token of eight digits were taken for a bind on the
    line network (a security review: guessed, never told)."""
    with pytest.raises(ConfigError, match="at least 16 characters that is not the example"):
        read(f"listen: 0.0.0.0:9000\ntoken: {token}\n")
    assert read(f"listen: 127.0.0.1:9000\ntoken: {token}\n").token == token.strip("'")


def test_a_token_that_is_no_text_is_refused_without_being_repeated():
    with pytest.raises(ConfigError) as err:
        read("listen: 0.0.0.0:9000\ntoken: 98765432109876543\n")
    assert "98765432109876543" not in str(err.value)
    assert "expected a string, got a number (not shown: a secret)" in str(err.value)


def test_a_short_token_off_this_machine_is_one_error_with_one_rule(tmp_path):
    """An IT administrator's trial: ``token: short1`` with a listen off the machine was told
    "at least 8 characters" and "a non-local bind needs a token ... set http.token" (one was
    set), then "16" with 10 characters.  Now one error, the 16-character rule, by config
    check too; on this machine the 8-character rule says the other."""
    from stationd.stationcheck import check_station

    with pytest.raises(ConfigError, match="at least 16 characters") as err:
        read("listen: 0.0.0.0:9000\ntoken: short1\n")
    assert "set http.token" not in str(err.value)
    with pytest.raises(ConfigError, match=r"at least 8 characters \(16 for a listen off"):
        read("listen: 127.0.0.1:9000\ntoken: short1\n")
    station = tmp_path / "station.yaml"
    station.write_text("http: {listen: '0.0.0.0:9000', token: short1}\n")
    errors = [str(e) for e in check_station(station).errors if "http" in str(e)]
    assert len(errors) == 1 and "at least 16 characters" in errors[0], errors
