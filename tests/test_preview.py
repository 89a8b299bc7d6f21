"""The live preview page, served by a running `mop perform`, loaded in a real headless Chromium."""
import json
import re
import shutil
import signal
import subprocess
import time
import urllib.request
from html.parser import HTMLParser

import numpy as np
import pytest

from session_files import mop_process, write_session

pytestmark = pytest.mark.slow   # a live session watched in a real Chromium

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


class Rows(HTMLParser):
    """Collects the text of every <td> per <tr data-performer=...> row and the #frame span."""

    def __init__(self):
        super().__init__()
        self.performers, self.frame = {}, None
        self._row = self._cell = None
        self._in_frame = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "tr" and "data-performer" in attrs:
            self._row = self.performers.setdefault(attrs["data-performer"], [])
        elif tag == "td" and self._row is not None:
            self._cell = []
        elif tag == "span" and attrs.get("id") == "frame":
            self._in_frame = True

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr":
            self._row = None
        elif tag == "span":
            self._in_frame = False

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)
        if self._in_frame:
            self.frame = int(data)


def dump_dom(url, profile):
    """The page's DOM after its scripts ran (Chromium waits for the virtual time budget)."""
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
               "--no-first-run", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}",
               "--virtual-time-budget=1500", "--dump-dom", url]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    parser = Rows()
    parser.feed(done.stdout)
    return parser, done.stdout


@pytest.mark.browser
@pytest.mark.skipif(CHROMIUM is None, reason="needs Chromium (apt-get install chromium)")
def test_preview_page_shows_follower_state_changing_in_chromium(tmp_path):
    import cv2
    path = write_session(tmp_path)
    process = mop_process("perform", path, "--realtime", "--loop", "--preview", "0")
    try:
        url = None
        deadline = time.monotonic() + 60
        while url is None and time.monotonic() < deadline:
            line = process.stderr.readline()
            match = re.search(r"^preview: (http://127\.0\.0\.1:\d+/)", line)
            url = match.group(1) if match else None
        assert url, "mop perform did not announce the preview page"
        while not process.stderr.readline().startswith("the show is on"):
            assert time.monotonic() < deadline + 60, "the show did not start"
        time.sleep(1.0)
        dumps = []
        for _ in range(3):
            dumps.append(dump_dom(url, tmp_path / "chromium")[0])
            time.sleep(0.7)
        state = json.loads(urllib.request.urlopen(url + "state.json", timeout=5).read())
        jpeg = urllib.request.urlopen(url + "frame.jpg", timeout=5).read()
        stream = urllib.request.urlopen(url + "stream.mjpg", timeout=5)
        head = stream.read(200)
        stream.close()
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=30)
    finally:
        process.kill()

    # the page's script filled in both performers' rows: status, action, progress, sigma, L
    for parsed in dumps:
        assert set(parsed.performers) == {"glove", "hand"}
        for _name, cells in parsed.performers.items():
            assert len(cells) == 7 and cells[1] in ("ok", "silent", "ended"), cells
    frames = [parsed.frame for parsed in dumps]
    assert frames == sorted(frames) and frames[0] < frames[-1]   # the page follows the show
    shown = [tuple(tuple(cells[2:4]) for cells in parsed.performers.values())
             for parsed in dumps]
    assert len(set(shown)) > 1, f"follower state did not change: {shown}"
    assert any(cells[2] != "rest" for parsed in dumps for cells in parsed.performers.values())

    assert state["performers"]["glove"]["status"] == "ok"
    assert state["timing"]["simulate"]["count"] > 0
    picture = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert picture.shape == (180, 320, 3)
    assert b"--mopframe" in head and b"image/jpeg" in head


def get(port, path, timeout=5.0):
    """(status, body) of one GET over a plain socket (HTTP/1.0: one request per connection)."""
    import socket
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as connection:
        connection.sendall(f"GET {path} HTTP/1.0\r\n\r\n".encode())
        data = b""
        while chunk := connection.recv(65536):
            data += chunk
    if not data:
        raise ConnectionResetError("the server closed the connection without an answer")
    head, _, body = data.partition(b"\r\n\r\n")
    return int(head.split()[1]), body


@pytest.mark.slow
def test_preview_server_stays_bounded_under_idle_and_junk_clients():
    """300 idle connections and 20,000 requests for distinct paths: the threads, the request
    counts and the time stay bounded, and the page answers again once the idle ones time out."""
    import socket
    import threading
    from mop.session.preview import PAGES, PreviewOutput
    preview = PreviewOutput(port=0, max_connections=16, timeout=1.0)
    try:
        preview.send({"frame": 3, "t": 0.12, "performers": {}, "characters": {}})
        base = threading.active_count()
        idle = []
        for _ in range(300):
            idle.append(socket.create_connection(("127.0.0.1", preview.port), timeout=5))
        time.sleep(0.3)
        assert threading.active_count() <= base + 16 + 2
        assert preview.server.refused >= 300 - 16 - 64      # the rest were closed at once
        deadline = time.monotonic() + 5.0                   # idle ones time out after 1 s
        while True:
            try:
                status, body = get(preview.port, "/state.json", timeout=1.0)
                break
            except OSError:
                assert time.monotonic() < deadline, "the server did not recover"
                time.sleep(0.2)
        assert status == 200 and json.loads(body)["frame"] == 3
        for connection in idle:
            connection.close()
        started = time.monotonic()
        for k in range(20_000):
            status, _ = get(preview.port, f"/junk/{k}")
            assert status == 404
        assert time.monotonic() - started < 120
        assert set(preview.requests) <= set(PAGES) | {"other"}
        assert preview.requests["other"] == 20_000
        assert threading.active_count() <= base + 16 + 2
    finally:
        preview.close()
