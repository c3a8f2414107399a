"""Seeing a release: the 3D viewer's point plan (budget, chunks, labels as released), the preview
server's browser and viewer routes and their refusals, ``siteline release browse`` as a user runs
it, and both pages in headless Chromium judged by the pixels of a screenshot."""

from __future__ import annotations

import json
import os
import stat
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from sitehelpers import chromium_path, manifest_doc, run_exe

from siteline import pipeline
from siteline.catalog.releases import release_location
from siteline.codes import NOT_OBSERVED
from siteline.errors import ReleaseError
from siteline.previews.browser import camera_figures, write_browser
from siteline.previews.cloud import budget_takes, decode_chunk
from siteline.previews.server import ReleaseAccess, make_server
from siteline.records.release import Manifest
from siteline.release.manifest import read_manifest


def _cloud(built, pair: int = 1):
    settings, cat, pub = built
    manifest = read_manifest(Path(pub.root))
    return manifest_doc(pub.root), pipeline.pair_cloud(cat, settings, manifest, pair)


def test_viewer_reads_every_point_with_the_labels_the_release_used(built) -> None:
    doc, cloud = _cloud(built)
    plan = cloud.plan(budget=10_000_000)  # more than the scenes hold: every point
    record = next(p for p in doc["lineage"]["pairs"] if p["id"] == 1)["labels"]["counts"]
    for side, key in ((1, "t1"), (2, "t2")):
        parts = [decode_chunk(plan.chunk(side, k)) for k in range(len(plan.chunks[side - 1]))]
        change = np.concatenate([p["change"] for p in parts])
        assert len(change) == cloud.side(side).point_count
        got = {
            "unchanged": int((change == 0).sum()),
            "changed": int((change == 1).sum()),
            "ignored": int((change == 255).sum()),
            "not_observed": int((change == NOT_OBSERVED).sum()),
        }
        assert got == {"not_observed": 0, **record[key]}
        # positions come back to the tiles' site-local metres within float32 of the centre
        xyz = np.concatenate([p["xyz"] for p in parts]).astype(np.float64) + plan.centre
        want = cloud.side(side).points(attributes=())
        assert np.allclose(np.sort(xyz, axis=0), np.sort(want.xyz_m, axis=0), atol=1e-3)
    with pytest.raises(IndexError, match="no chunk"):
        plan.chunk(1, len(plan.chunks[0]))


def test_a_small_budget_draws_the_whole_site_coarsely(built) -> None:
    _, cloud = _cloud(built)
    tiles = cloud.scenes.t1
    take, level = budget_takes(tiles, 8_000)
    assert 4_000 <= take.sum() <= 8_000 and level >= 0
    plan = cloud.plan(budget=16_000)
    xyz = np.concatenate([decode_chunk(plan.chunk(1, k))["xyz"] for k in range(len(plan.chunks[0]))])
    assert 4_000 <= len(xyz) <= 8_000
    whole = tiles.points(attributes=()).xyz_m
    span = np.ptp(xyz[:, :2], axis=0) / np.ptp(whole[:, :2], axis=0)
    assert (span > 0.9).all()  # the level of detail covers the site, not a corner of it


def test_cameras_are_drawn_where_the_items_were_rendered(built) -> None:
    doc, cloud = _cloud(built)
    out = cloud.plan(budget=20_000).to_dict("/browse/rel/1.0.0/")
    items = {it["id"]: it for it in doc["items"] if it["pair"] == 1}
    assert {c["item"] for c in out["cameras"]} == set(items)
    for cam in out["cameras"]:
        centre = np.asarray(cam["points"][0]) + out["centre"]
        assert np.allclose(centre, camera_figures(items[cam["item"]]["camera"])["centre"], atol=1e-3)
        assert cam["browser"] == f"/browse/rel/1.0.0/#item={cam['item']}"
    json.dumps(out)


def test_pair_cloud_refuses_a_pair_the_release_lacks(built) -> None:
    settings, cat, pub = built
    doc = manifest_doc(Path(pub.root))
    with pytest.raises(ReleaseError, match=r"has no pair 99 \(its pairs: 1, 2\)"):
        pipeline.pair_cloud(cat, settings, Manifest.from_dict(doc), 99)


@pytest.fixture(scope="module")
def server(built) -> Iterator[str]:
    settings, cat, _ = built

    def locate(name: str, version: str):
        with cat.transaction() as s:
            return release_location(s, name, version)

    srv = make_server(
        settings.home,
        "127.0.0.1",
        0,
        ReleaseAccess(locate, lambda doc, p: pipeline.pair_cloud(cat, settings, doc, p)),
    )
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{srv.server_address[1]}"
    srv.shutdown()
    srv.server_close()


def _get(url: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def test_server_routes_and_refusals(built, server) -> None:
    _, _, pub = built
    root = Path(pub.root)
    status, body = _get(server + "/")
    assert status == 200 and b'href="/browse/rel/1.0.0/"' in body and b'href="/3d/rel/1.0.0/2/"' in body
    status, body = _get(server + "/browse/rel/1.0.0/")
    doc = manifest_doc(root)
    assert status == 200 and all(it["id"].encode() in body for it in doc["items"])
    it = doc["items"][0]
    rel = f"{it['split']}/A/{it['id']}.png"
    assert _get(f"{server}/browse/rel/1.0.0/files/{rel}") == (200, (root / rel).read_bytes())
    status, plan = _get(server + "/3d/rel/1.0.0/1/plan.json?budget=20000")
    plan = json.loads(plan)
    assert status == 200 and plan["points"]["t1"] + plan["points"]["t2"] <= 20_000
    status, chunk = _get(server + "/3d/rel/1.0.0/1/t2/0.bin?budget=20000")
    assert status == 200 and len(decode_chunk(chunk)["xyz"]) == plan["chunks"]["t2"][0]
    status, body = _get(server + "/3d/rel/1.0.0/1/")
    assert status == 200 and b"/static/three/three.module.js" in body
    assert _get(server + "/static/three/OrbitControls.js")[0] == 200
    for path, code, words in [
        ("/browse/rel/9.9.9/", 404, b"no release rel 9.9.9"),
        ("/browse/rel/1.0.0/files/%2e%2e/%2e%2e/catalog.sqlite", 404, b"has no"),
        ("/browse/rel/1.0.0/files/.draft", 404, b"has no"),
        ("/3d/rel/1.0.0/7/plan.json", 404, b"has no pair 7"),
        ("/3d/rel/1.0.0/x/plan.json", 400, b"the pair is a number"),  # a malformed request
        ("/3d/rel/1.0.0/1/plan.json?budget=5", 400, b"budget"),
        ("/3d/rel/1.0.0/1/t1/9999.bin", 404, b"no chunk 9999"),
        ("/static/../server.py", 404, b""),
    ]:
        status, body = _get(server + path)
        assert status == code and words in body, (path, status, body)


def test_server_without_a_catalog_browses_published_releases_but_not_3d(built) -> None:
    settings, _, _ = built
    srv = make_server(settings.home, "127.0.0.1", 0)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{srv.server_address[1]}"
    try:
        assert _get(base + "/browse/rel/1.0.0/")[0] == 200
        status, body = _get(base + "/3d/rel/1.0.0/1/plan.json")
        assert status == 503 and b"catalog" in body
    finally:
        srv.shutdown()
        srv.server_close()


def test_release_browse_writes_a_page_beside_the_release(built, tmp_path) -> None:
    settings, _, pub = built
    root = Path(pub.root)
    before = sorted(p.name for p in root.parent.iterdir())
    r = run_exe(settings.home, "release", "browse", "rel", "1.0.0", "--out", str(tmp_path / "page.html"))
    assert r.returncode == 0, r.stderr
    page = (tmp_path / "page.html").read_text()
    assert "file://" in r.stdout and all(it["id"] in page for it in manifest_doc(root)["items"])
    # images addressed relative to the page, so it opens from the disk
    assert json.loads(page.split('type="application/json">')[1].split("</script>")[0])["images"].startswith(
        "../"
    )
    r = run_exe(settings.home, "release", "browse", "rel", "1.0.0", "--out", str(root / "x.html"))
    assert (
        r.returncode == 2 and "inside the release" in r.stderr + r.stdout and not (root / "x.html").exists()
    )
    r = run_exe(settings.home, "release", "browse", "rel", "7.7.7")
    assert r.returncode == 2 and "no release rel 7.7.7" in r.stderr + r.stdout
    assert sorted(p.name for p in root.parent.iterdir()) == before
    # a folder given as --out that already holds an unrelated rel-1.0.0.html: refused like a file
    folder = tmp_path / "pages"
    folder.mkdir()
    (folder / "rel-1.0.0.html").write_text("my notes")
    r = run_exe(settings.home, "release", "browse", "rel", "1.0.0", "--out", str(folder))
    assert (
        r.returncode == 2 and "--force" in r.stderr and (folder / "rel-1.0.0.html").read_text() == "my notes"
    )
    r = run_exe(settings.home, "release", "browse", "rel", "1.0.0", "--out", str(folder), "--force")
    assert r.returncode == 0 and "<html" in (folder / "rel-1.0.0.html").read_text().lower()
    # a FIFO is never replaced, --force or not
    fifo = tmp_path / "pipe.html"
    os.mkfifo(fifo)
    for extra in ((), ("--force",)):
        r = run_exe(settings.home, "release", "browse", "rel", "1.0.0", "--out", str(fifo), *extra)
        assert (
            r.returncode == 2 and "not a regular file" in r.stderr and stat.S_ISFIFO(os.lstat(fifo).st_mode)
        )


# --- in headless Chromium --------------------------------------------------------------------------

SOLID = {"A": (0, 0, 255), "B": (255, 255, 0)}


def _fake_release(root: Path, n: int, size: tuple[int, int] = (40, 30)) -> dict:
    """A release folder of ``n`` items whose A is blue, B yellow, and whose mask marks the left half
    changed (label 255 there) and the bottom quarter of the right half ignored: enough for the browser,
    whose pixels are then known."""
    w, h = size
    items = []
    for k in range(n):
        split = ("train", "val", "test")[k % 3]
        iid = f"site_p{k % 7 + 1:04d}_v{k:04d}"
        for folder, img in (
            ("A", Image.new("RGB", size, SOLID["A"])), ("B", Image.new("RGB", size, SOLID["B"])),
            ("label", Image.fromarray(np.where(np.arange(w)[None, :] < w // 2, 255, 0).repeat(h, 0).astype(np.uint8))),
            ("ignore", Image.fromarray(np.pad(np.full((h // 4, w // 2), 255, np.uint8), ((h - h // 4, 0), (w - w // 2, 0))))),
        ):  # fmt: skip
            (root / split / folder).mkdir(parents=True, exist_ok=True)
            img.save(root / split / folder / f"{iid}.png")
        items.append({
            "id": iid, "split": split, "pair": k % 7 + 1, "view": k, "strategy": ("oblique-none-0", "nadir-x-1")[k % 2],
            "coverage": 0.9, "valid": 1.0 - (k % 10) / 20, "change_ratio": (k % 13) / 13, "size_px": [w, h],
            "padded_px": [w, h], "ignore": {}, "filled": 0.0,
        })  # fmt: skip
    pairs = {sp: sorted({it["pair"] for it in items if it["split"] == sp}) for sp in ("train", "val", "test")}
    doc = {"format": 2, "name": "site", "version": "1.0.0", "created": "2026-11-28T00:00:00+00:00", "code_version": "test",
           "files": [], "splits": pairs, "items": items, "lineage": {"pairs": []}}  # fmt: skip
    (root / "manifest.json").write_text(json.dumps(doc))
    return doc


@pytest.fixture(scope="module")
def chromium():
    chromium = chromium_path()  # a system package `make test` installs; missing, the page tests fail
    from playwright.sync_api import sync_playwright  # a dev dependency

    with sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path=str(chromium),
            args=[
                "--no-sandbox",
                "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader",
                "--ignore-gpu-blocklist",
            ],
        )
        yield browser
        browser.close()


def _open(browser, url: str, size=(1200, 800)):
    page = browser.new_page(viewport={"width": size[0], "height": size[1]})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_function("document.body.dataset.ready || document.body.dataset.error", timeout=60_000)
    page.wait_for_function("[...document.images].every(i => i.complete)", timeout=60_000)
    assert not errors and page.evaluate("document.body.dataset.error") is None, errors
    return page


def _pixels(page, selector: str) -> np.ndarray:
    import io

    return np.asarray(Image.open(io.BytesIO(page.locator(selector).screenshot())).convert("RGB")).astype(int)


def _near(px: np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> bool:
    return bool(np.abs(px - np.asarray(rgb)).max() <= tol)


def test_browser_swipe_and_mask_in_chromium(chromium, tmp_path) -> None:
    root = tmp_path / "releases" / "site" / "1.0.0"
    doc = _fake_release(root, 6)
    page_path = write_browser(root)
    iid = doc["items"][2]["id"]
    page = _open(chromium, f"{page_path.as_uri()}#item={iid}&mode=swipe&swipe=30&mask=none")
    px = _pixels(page, "#swipe")
    h, w = px.shape[:2]
    assert _near(px[h // 2, int(w * 0.15)], SOLID["A"]) and _near(px[h // 2, int(w * 0.7)], SOLID["B"])
    # the mask over both at full opacity: the left half red (changed), the right half untouched
    page.goto(f"{page_path.as_uri()}#item={iid}&mode=swipe&swipe=30&mask=both&opacity=1")
    page.reload()
    page.wait_for_function("[...document.images].every(i => i.complete)")
    px = _pixels(page, "#swipe")
    assert _near(px[h // 2, int(w * 0.1)], (255, 26, 26), 60)  # A under the mask
    assert _near(px[h // 2, int(w * 0.4)], (255, 26, 26), 60)  # B under the mask
    assert _near(px[h // 2, int(w * 0.8)], SOLID["B"])
    # side by side: two stages, A then B; the arrow key steps to the next item
    page.select_option("#d-mode", "side")
    stages = page.locator(".stage")
    assert stages.count() == 2
    page.keyboard.press("ArrowRight")
    assert doc["items"][3]["id"] in page.evaluate("location.hash")


def _view(page) -> dict:
    """What the detail view shows: its item and every control a copied address must carry."""
    return page.evaluate("""() => ({
        open: !document.getElementById("detail").hidden, title: document.getElementById("d-title").textContent,
        ...Object.fromEntries(["d-mode", "d-mask", "d-opacity", "d-swipe", "f-split", "f-sort", "f-thumb", "f-chg-min", "f-chg-max"]
            .map(id => [id, document.getElementById(id).value])),
        ignore: document.getElementById("d-ignore").checked, count: document.getElementById("count").textContent })""")


def test_a_copied_address_reopens_the_same_view(chromium, tmp_path) -> None:
    """The whole view is written into the address as it changes, a copied address reopens it in a new
    tab, and editing the address of an open tab changes the view (hashchange)."""
    root = tmp_path / "releases" / "site" / "1.0.0"
    doc = _fake_release(root, 30)
    page_path = write_browser(root)
    page = _open(chromium, page_path.as_uri(), (1400, 800))
    page.select_option("#f-split", "val")
    page.select_option("#f-sort", "-change")
    page.fill("#f-chg-min", "10")
    page.dispatch_event("#f-chg-min", "input")
    page.locator(".cell").first.click()
    page.select_option("#d-mode", "side")
    page.select_option("#d-mask", "A")
    page.locator("#d-opacity").fill("30")
    page.locator("#d-ignore").uncheck()
    page.wait_for_timeout(300)  # the slider's write waits for it to rest
    seen = _view(page)
    href = page.evaluate("location.href")
    for key in (
        "item=",
        "mode=side",
        "mask=A",
        "opacity=0.3",
        "ignore=0",
        "split=val",
        "sort=-change",
        "chg=10-100",
    ):
        assert key in href, (key, href)
    again = _open(chromium, href, (1400, 800))
    assert _view(again) == seen and seen["open"] and seen["d-mode"] == "side"
    # an address edited in the open tab: another item in swipe mode, no filters
    other = doc["items"][4]["id"]
    again.evaluate(f"location.hash = '#item={other}&mode=swipe&swipe=30'")
    again.wait_for_function(f"document.getElementById('d-title').textContent.startsWith('{other}')")
    now = _view(again)
    assert (
        now["d-mode"] == "swipe"
        and now["d-swipe"] == "30"
        and now["f-split"] == ""
        and now["d-mask"] == "both"
    )
    assert now["count"].startswith("30 of 30")
    again.evaluate("location.hash = ''")
    again.wait_for_function("document.getElementById('detail').hidden")


def test_grid_fills_the_width_and_mask_thumbnails_use_the_legend_colours(chromium, tmp_path) -> None:
    root = tmp_path / "releases" / "site" / "1.0.0"
    _fake_release(root, 12)
    page_path = write_browser(root)
    page = _open(chromium, page_path.as_uri() + "#thumb=label", (1400, 800))
    page.wait_for_function("[...document.images].every(i => i.complete)")
    right = page.evaluate(
        "Math.max(...[...document.querySelectorAll('.cell')].map(c => c.getBoundingClientRect().right))"
    )
    width = page.evaluate("document.getElementById('grid-scroll').clientWidth")
    assert width - right < 12, (right, width)  # at 1400 px five columns fill the row (200 px were left)
    px = _pixels(page, ".cell .mthumb >> nth=0")
    h, w = px.shape[:2]
    shown = h * 40 / 30  # the 40 x 30 mask fitted to the thumbnail's height, centred
    x = lambda f: int((w - shown) / 2 + f * shown)  # noqa: E731
    assert _near(px[h // 2, x(0.25)], (255, 26, 26), 60)  # changed: red, as the legend says
    assert _near(px[h // 2, x(0.75)], (0, 0, 0), 30)  # unchanged: black
    # ignore (the bottom quarter of the right half) is hatched: pale blue stripes with black between
    ign = px[int(h * 0.8) : h - 3, x(0.55) : x(0.97)]
    pale = (ign[..., 2] > 120).mean()
    assert 0.15 < pale < 0.7, pale  # stripes, not a solid fill
    assert (px[int(h * 0.8) : h - 3, x(0.25)][:, 0] > 200).all()  # changed is solid


def test_ignore_is_hatched_over_the_image(chromium, tmp_path) -> None:
    root = tmp_path / "releases" / "site" / "1.0.0"
    doc = _fake_release(root, 3, (200, 160))
    page_path = write_browser(root)
    page = _open(
        chromium, f"{page_path.as_uri()}#item={doc['items'][0]['id']}&mode=side&mask=B&opacity=1", (1400, 800)
    )
    px = _pixels(page, ".stage >> nth=1")
    h, w = px.shape[:2]
    ign = px[int(h * 0.8) : h - 2, int(w * 0.55) : w - 2]
    plain = np.abs(ign - np.asarray(SOLID["B"])).max(axis=2) <= 40
    assert 0.3 < plain.mean() < 0.85, plain.mean()  # B's own yellow shows between the stripes


def test_browser_of_5000_items_stays_light(chromium, tmp_path) -> None:
    root = tmp_path / "releases" / "site" / "1.0.0"
    doc = _fake_release(root, 5000, (16, 12))
    page_path = write_browser(root)
    start = time.perf_counter()
    page = _open(chromium, page_path.as_uri())
    loaded = time.perf_counter() - start
    cells = page.locator(".cell").count()
    assert 0 < cells < 200  # only the rows in sight are drawn
    start = time.perf_counter()
    page.evaluate("document.getElementById('grid-scroll').scrollTop = 1e9")
    last = max(it["id"] for it in doc["items"])  # the grid is sorted by id
    page.wait_for_function(f"!!document.querySelector('img[alt=\"{last}\"]')")
    scrolled = time.perf_counter() - start
    page.select_option("#f-split", "val")
    assert (
        page.locator("#count")
        .inner_text()
        .startswith(f"{sum(it['split'] == 'val' for it in doc['items'])} of 5000")
    )
    print(f"\n5,000 items: page ready in {loaded:.2f} s ({page.evaluate('document.body.dataset.ready')} ms of script), "
          f"{cells} cells in the DOM, scrolled to the last row in {scrolled:.2f} s")  # fmt: skip


def _scene_pixels(page) -> np.ndarray:
    """The canvas right of the panel (whose class legend has coloured swatches)."""
    right = int(page.evaluate("document.getElementById('panel').getBoundingClientRect().right")) + 4
    return _pixels(page, "canvas")[:, right:]


def test_viewer_draws_change_in_red_and_green_in_chromium(chromium, server) -> None:
    page = _open(chromium, server + "/3d/rel/1.0.0/1/", (1100, 700))
    px = _scene_pixels(page)
    red = (px[..., 0] > 180) & (px[..., 1] < 80) & (px[..., 2] < 80)
    green = (px[..., 1] > 120) & (px[..., 0] < 90) & (px[..., 2] < 110)
    assert red.sum() > 500 and green.sum() > 2000, (red.sum(), green.sum())
    page.check("#changed")
    page.wait_for_timeout(300)
    px = _scene_pixels(page)
    red2 = (px[..., 0] > 180) & (px[..., 1] < 80) & (px[..., 2] < 80)
    green2 = (px[..., 1] > 120) & (px[..., 0] < 90) & (px[..., 2] < 110)
    assert red2.sum() > 500 and green2.sum() < 50
    page.uncheck("#t1")
    page.uncheck("#t2")
    page.wait_for_timeout(300)
    px = _scene_pixels(page)
    assert ((px[..., 0] > 180) & (px[..., 1] < 80) & (px[..., 2] < 80)).sum() == 0


def test_clicking_a_camera_opens_its_item_in_the_browser(chromium, server) -> None:
    page = _open(chromium, server + "/3d/rel/1.0.0/2/", (1100, 700))
    assert not page.is_checked("#cams")  # frusta are drawn when asked
    page.check("#cams")
    plan = json.loads(_get(server + "/3d/rel/1.0.0/2/plan.json")[1])
    panel = page.evaluate("document.getElementById('panel').getBoundingClientRect().right")
    # a camera in sight, not under the panel
    spots = {c["item"]: page.evaluate(f"window.siteline3d.cameraAt('{c['item']}')") for c in plan["cameras"]}
    item, at = next(
        (i, p) for i, p in spots.items() if p and panel + 10 < p["x"] < 1090 and 10 < p["y"] < 690
    )
    with page.context.expect_page() as opened:
        page.mouse.click(at["x"], at["y"])
    shown = opened.value
    shown.wait_for_load_state("domcontentloaded")  # a page just opened may not have its body yet
    shown.wait_for_function("document.body.dataset.ready")
    assert shown.url.endswith(f"/browse/rel/1.0.0/#item={item}")
    assert shown.locator("#d-title").inner_text().startswith(item) and shown.locator("#detail").is_visible()


def test_viewer_status_is_true_and_eye_dome_lighting_shades_edges(chromium, server) -> None:
    plan = json.loads(_get(server + "/3d/rel/1.0.0/1/plan.json?budget=60000")[1])
    page = _open(chromium, server + "/3d/rel/1.0.0/1/?budget=60000", (1100, 700))
    planned = plan["points"]["t1"] + plan["points"]["t2"]
    total = plan["scene_points"]["t1"] + plan["scene_points"]["t2"]
    text = page.locator("#counts").inner_text()
    assert planned < total and f"{planned:,} loaded of the {total:,}" in text, text
    assert "a budget of 60,000 points" in text and f"t1 to level {plan['levels']['t1']}" in text, text
    assert page.is_checked("#edl") and not page.is_checked("#cams")
    lit = _scene_pixels(page)
    page.uncheck("#edl")
    page.wait_for_timeout(200)
    flat = _scene_pixels(page)
    drawn = np.abs(flat - np.array([0x15, 0x18, 0x1D])).max(axis=2) > 20  # points, not the background
    assert drawn.mean() > 0.05
    ratio = (lit.sum(axis=2) / np.maximum(flat.sum(axis=2), 1))[drawn]
    darker = (ratio < 0.7).mean()
    # eye-dome lighting darkens the points at depth steps (edges, the backs of objects), not the rest
    assert 0.02 < darker < 0.5 and np.median(ratio) > 0.8, (darker, np.median(ratio))


def test_chunks_read_from_many_threads_at_once_are_whole(built) -> None:
    from concurrent.futures import ThreadPoolExecutor

    _, cloud = _cloud(built, 2)
    plan = cloud.plan(budget=40_000)
    jobs = [(s, k) for s in (1, 2) for k in range(len(plan.chunks[s - 1]))] * 3
    with ThreadPoolExecutor(8) as pool:
        got = list(pool.map(lambda job: plan.chunk(*job), jobs))
    alone = {job: plan.chunk(*job) for job in set(jobs)}
    assert all(data == alone[job] for job, data in zip(jobs, got, strict=True))
