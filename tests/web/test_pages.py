"""The browsers the screens' tests share (one of each kind per worker, ``conftest.Browsers``):
a test gets one as a newly started browser would be."""

from __future__ import annotations

from tests.web.pages import Page


def test_a_fresh_browser_keeps_no_cookie_of_any_port_and_no_download(page: Page,
                                                                     live_server) -> None:
    a, b = live_server(), live_server()        # two servers: two ports of 127.0.0.1
    page.get(a.url)
    page.js("document.cookie = 'left=over; path=/; max-age=3600'")
    page.get(b.url)
    assert "left=over" in str(page.js("return document.cookie"))   # ports share cookies
    (page.downloads / "report.csv").write_text("old")
    page.size(1280, 800)
    page.fresh()
    assert page.js("return location.href") == "about:blank"
    assert list(page.downloads.iterdir()) == []
    for server in (a, b):
        page.get(server.url)
        assert page.js("return document.cookie") == ""
    assert page.js("return [window.innerWidth, window.innerHeight]") == [1920, 1080]
