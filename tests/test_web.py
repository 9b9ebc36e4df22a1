"""The web page and the preview picture, in a real browser: Debian's Chromium, headless, against a
real ``voxelastic serve`` with a token configured (the page asks for it and sends it as Bearer)."""

from __future__ import annotations

import io
import re
import shutil
import subprocess

import numpy as np
import pytest
from service_helpers import Server, cantilever, shared_cache_dir

TOKEN = "page-test-token"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = Server(tmp_path_factory.mktemp("web") / "data", shared_cache_dir(tmp_path_factory), workers=1, token=TOKEN)
    srv.start()
    yield srv
    srv.close()


@pytest.fixture(scope="module")
def finished(server):
    job = server.wait(server.submit_ok(cantilever(16)), timeout=180)
    assert job["status"] == "succeeded", job
    return job


def browser(*args: str, profile) -> str:
    """Headless Chromium (flags: no sandbox as root, nothing fetched from outside, a fresh profile)."""
    if CHROMIUM is None:
        pytest.skip("needs Debian's chromium (.ci/run installs it)")
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={profile}", "--virtual-time-budget=15000"]
    out = subprocess.run([CHROMIUM, *flags, *args], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def object_pixels(png: bytes) -> float:
    """Share of pixels that are coloured (neither white nor grey): the object and its colour bar."""
    from PIL import Image

    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    return float((np.abs(image - image.max(axis=2, keepdims=True)).sum(axis=2) > 60).mean())


def test_preview_png_of_a_finished_job(server, finished):
    r = server.client.get(f"/jobs/{finished['id']}/preview.png")
    assert r.status_code == 200 and r.headers["content-type"] == "image/png", r.text
    assert r.content.startswith(b"\x89PNG")
    assert object_pixels(r.content) > 0.05
    assert finished["result"]["preview_url"] == f"/jobs/{finished['id']}/preview.png"
    for name, url in finished["result"]["files"].items():
        got = server.client.get(url)
        assert got.status_code == 200, (name, got.text)
    # every job route keeps its token: without it, no picture
    import httpx

    assert httpx.get(server.url + f"/jobs/{finished['id']}/preview.png").status_code == 401


def test_a_job_without_surface_has_no_picture_and_says_why(server):
    spec = cantilever(12)
    spec["output"]["surface"] = False
    job = server.wait(server.submit_ok(spec), timeout=180)
    r = server.client.get(f"/jobs/{job['id']}/preview.png")
    assert r.status_code == 404 and "output.surface" in r.json()["detail"]
    assert job["result"]["preview_url"] is None


def test_the_page_is_static_and_needs_no_token(server):
    import httpx

    page = httpx.get(server.url + "/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert "<form" in page.text
    assert not re.search(r"""(src|href)=["']https?://""", page.text)  # nothing from elsewhere: works offline
    assert httpx.get(server.url + "/jobs").status_code == 401


def test_the_page_in_chromium_lists_the_job_and_shows_its_picture(server, finished, tmp_path):
    dom = browser("--dump-dom", f"{server.url}/#token={TOKEN}", profile=tmp_path / "profile")
    row = re.search(rf'<tr data-job="{finished["id"]}" data-status="succeeded">(.*?)</tr>', dom, re.S)
    assert row, dom[-3000:]
    img = re.search(r'<img class="preview"[^>]*>', row.group(1))
    assert img and re.search(r'data-loaded="(\d+)"', img.group(0)), row.group(1)[:2000]
    assert int(re.search(r'data-loaded="(\d+)"', img.group(0)).group(1)) > 100  # a real picture, decoded
    assert ".vtkhdf" in row.group(1) and ".h5" in row.group(1)
    shot = tmp_path / "page.png"
    browser(f"--screenshot={shot}", "--window-size=1280,900", f"{server.url}/#token={TOKEN}",
            profile=tmp_path / "profile2")
    assert object_pixels(shot.read_bytes()) > 0.01  # the picture is on the page


def test_the_page_without_a_token_asks_for_one(server, tmp_path):
    dom = browser("--dump-dom", f"{server.url}/", profile=tmp_path / "profile")
    assert "This server needs a token" in dom
    assert "data-job=" not in dom
