"""The service as users run it (`make serve`: Prefect server, worker, watcher, preview server), driven
from outside like a user: uploads dropped into the watched folder, label corrections imported at once,
a worker killed mid-pair, a worker and its flow process killed together (a machine failure), a page of
the UI looked at in headless Chromium. Prints drop-to-release and recovery times. Slow (`make test-all`)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import laspy
import numpy as np
import pytest
from sitehelpers import chromium_path, epoch_dirs

REPO = Path(__file__).resolve().parents[2]
EXE = str(Path(sys.executable).with_name("siteline"))
pytestmark = [pytest.mark.slow, pytest.mark.e2e]
TERMINAL = {"COMPLETED", "FAILED", "CRASHED", "CANCELLED"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _until(what: str, check, timeout_s: float, every_s: float = 2.0):  # noqa: ANN001, ANN202
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        got = check()
        if got:
            return got
        time.sleep(every_s)
    raise AssertionError(f"{what}: not within {timeout_s:.0f} s")


class Service:
    """`deploy/serve.sh` in its own session, on free ports, and what a user sees of it (the REST API)."""

    def __init__(self, home: Path) -> None:
        self.home, port, preview = home, _free_port(), _free_port()
        self.api = f"http://127.0.0.1:{port}/api"
        self.preview = f"http://127.0.0.1:{preview}"
        keep = {k: v for k, v in os.environ.items() if not k.startswith(("SITELINE_", "PREFECT_"))}
        self.env = keep | {
            "SITELINE_HOME": str(home), "PREFECT_PORT": str(port), "SITELINE_PREVIEW_URL": self.preview,
            "PREFECT_API_URL": self.api, "SITELINE_STABLE_SECONDS": "2", "COLUMNS": "200",
        }  # fmt: skip
        self.log = open(home.parent / "serve.out", "w")  # noqa: SIM115 (closed in stop)
        self.proc = subprocess.Popen(["bash", "deploy/serve.sh"], cwd=REPO, env=self.env, stdout=self.log,
                                     stderr=subprocess.STDOUT, start_new_session=True)  # fmt: skip
        _until(
            "the service to start",
            lambda: "drop missions into" in (home.parent / "serve.out").read_text(),
            240,
        )

    def stop(self) -> None:
        os.killpg(self.proc.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout=30)
        finally:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.log.close()

    def siteline(self, *argv: str) -> subprocess.CompletedProcess:
        return subprocess.run([EXE, *argv], env=self.env, capture_output=True, text=True, timeout=600)

    def runs(self) -> list[dict]:
        r = httpx.post(
            f"{self.api}/flow_runs/filter", json={"sort": "START_TIME_ASC", "limit": 200}, timeout=30
        )
        r.raise_for_status()
        return r.json()

    def logs(self, run_id: str) -> str:
        r = httpx.post(f"{self.api}/logs/filter", json={"logs": {"flow_run_id": {"any_": [run_id]}}, "limit": 200},
                       timeout=30)  # fmt: skip
        return "\n".join(entry["message"] for entry in r.json())

    def processes(self, marker: str) -> list[int]:
        """The service's processes (descendants of serve.sh: flow runs live in sessions of their own)
        whose command line holds ``marker``."""
        parent, cmd = {}, {}
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                try:
                    parent[int(entry.name)] = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
                    cmd[int(entry.name)] = (
                        (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
                    )
                except (OSError, IndexError, ValueError):
                    continue

        def descends(pid: int) -> bool:
            while pid > 1:
                if pid == self.proc.pid:
                    return True
                pid = parent.get(pid, 0)
            return False

        return [pid for pid, line in cmd.items() if marker in line and descends(pid)]

    def artifacts(self, key: str) -> list[dict]:
        r = httpx.post(f"{self.api}/artifacts/filter", json={"artifacts": {"key": {"any_": [key]}}, "sort": "CREATED_DESC"},
                       timeout=30)  # fmt: skip
        r.raise_for_status()
        return r.json()

    def versions(self) -> list[str]:
        root = self.home / "releases" / "demo-cd"
        return (
            sorted(p.name for p in root.iterdir() if (p / "manifest.json").is_file()) if root.is_dir() else []
        )

    def drop(self, mission: Path, name: str | None = None) -> None:
        dest = self.home / "uploads" / (name or mission.name)
        shutil.copytree(mission, dest)
        (dest / ".upload-complete").touch()

    def settled(self) -> bool:
        runs = self.runs()
        return bool(runs) and all(r["state_type"] in TERMINAL for r in runs)


def _corrected(svc: Service, scene: int, tmp: Path, version: int) -> Path:
    """A correction of ``scene``: a 30 m box of its points made vehicles."""
    out = tmp / f"s{scene}-v{version}.las"
    assert svc.siteline("scene", "export", str(scene), "--out", str(out)).returncode == 0
    las = laspy.read(out)
    cls = np.asarray(las.classification).copy()
    x, y = np.asarray(las.x), np.asarray(las.y)
    box = (
        (abs(x - np.median(x) + 10 * version) < 15) & (abs(y - np.median(y)) < 15) & (cls != 255) & (cls != 5)
    )
    cls[box] = 5
    las.classification = cls
    las.write(out)
    return out


def _scene_run(svc: Service, name: str) -> dict:
    return _until(f"a run {name}", lambda: next((r for r in svc.runs() if r["name"] == name), None), 120)


def _rendering(svc: Service, name: str) -> None:
    run = _scene_run(svc, name)
    _until(
        f"{name} to be rendering",
        lambda: "views" in svc.logs(run["id"]) or "renders" in svc.logs(run["id"]),
        300,
        1.0,
    )


def _screenshots(svc: Service, run_id: str, why_id: str, tmp_path: Path) -> None:
    """The crashed run's why-artifact in the UI, the release browser and a pair in 3D, looked at in
    headless Chromium (Playwright, when installed): the texts and images are there; screenshots under
    SITELINE_SCREENSHOTS (docs/images when set so) for the docs."""
    from playwright.sync_api import sync_playwright  # a dev dependency

    # an empty SITELINE_SCREENSHOTS is unset, not the working directory (shots once landed at the root)
    out = Path(os.environ.get("SITELINE_SCREENSHOTS") or tmp_path / "shots")
    out.mkdir(parents=True, exist_ok=True)
    ui = svc.api.removesuffix("/api")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(chromium_path()),
                                    args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"])  # fmt: skip
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.goto(f"{ui}/artifacts/artifact/{why_id}")
        page.get_by_text("Why scene-1-labels-v3 stopped").first.wait_for(timeout=60_000)
        page.get_by_text("no heartbeat", exact=False).first.wait_for(timeout=10_000)
        page.screenshot(path=out / "service-why.png")
        page.goto(f"{ui}/runs/flow-run/{run_id}?tab=Artifacts")
        page.wait_for_timeout(5000)
        page.screenshot(path=out / "service-run-artifacts.png")
        for name, url in (("browser.png", f"{svc.preview}/browse/demo-cd/4.0.0/"),
                          ("viewer-3d.png", f"{svc.preview}/3d/demo-cd/4.0.0/1/")):  # fmt: skip
            page.goto(url)
            page.wait_for_function(
                "document.body.dataset.ready || document.body.dataset.error", timeout=120_000
            )
            assert page.evaluate("document.body.dataset.error") is None
            page.wait_for_timeout(1000)
            page.screenshot(path=out / name)
        browser.close()


def test_the_service(tmp_path, synth_site) -> None:
    missions = epoch_dirs(synth_site)
    svc = Service(tmp_path / "home")
    figures: dict[str, float] = {}
    try:
        # the site's release settings are what the service builds with
        assert svc.siteline("site", "update", "demo", "--views", "6").returncode == 0

        # three uploads, one after another -> two releases (the third adds pairs only: a minor version),
        # images of at least 256 px (512: auto scale)
        t0 = time.monotonic()
        svc.drop(missions[0])
        svc.drop(missions[1])
        _until("release 1.0.0", lambda: "1.0.0" in svc.versions(), 600)
        figures["two uploads -> 1.0.0 (s)"] = time.monotonic() - t0
        t0 = time.monotonic()
        svc.drop(missions[2])
        _until("release 1.1.0", lambda: "1.1.0" in svc.versions(), 600)
        figures["third upload -> 1.1.0 (s)"] = time.monotonic() - t0
        manifest = json.loads((svc.home / "releases" / "demo-cd" / "1.1.0" / "manifest.json").read_text())
        assert manifest["lineage"]["parameters"]["views"] == 6
        assert (
            all(max(it["size_px"]) >= 512 for it in manifest["items"])
            and len(manifest["lineage"]["pairs"]) == 2
        )

        # the same mission dropped again under another name: ingested as nothing new, no event, no release
        _until("the service to settle", svc.settled, 300)
        scene_runs = sum(r["name"].startswith("scene-") for r in svc.runs())
        svc.drop(missions[1], name="second-copy-of-e01")
        _until("the re-drop's ingest", lambda: any(r["name"].startswith("ingest-demo-second-copy") and r["state_type"] in TERMINAL for r in svc.runs()), 300)  # fmt: skip
        time.sleep(15)
        assert sum(r["name"].startswith("scene-") for r in svc.runs()) == scene_runs
        assert svc.versions() == ["1.0.0", "1.1.0"]

        # two label imports at once: no failed run, one new release with both (the other up to date)
        fixes = [_corrected(svc, scene, tmp_path, 2) for scene in (1, 3)]
        imports = [subprocess.Popen([EXE, "labels", "import", str(scene), str(f)], env=svc.env, stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True) for scene, f in zip((1, 3), fixes, strict=True)]  # fmt: skip
        assert all(p.wait(timeout=300) == 0 for p in imports)
        _until("both label runs", lambda: sum(r["name"].endswith("labels-v2") for r in svc.runs()) == 2, 120)
        _until("the service to settle", svc.settled, 900)
        assert not [r["name"] for r in svc.runs() if r["state_type"] != "COMPLETED"]
        assert svc.versions() == ["1.0.0", "1.1.0", "2.0.0"]
        lineage = json.loads((svc.home / "releases" / "demo-cd" / "2.0.0" / "manifest.json").read_text())[
            "lineage"
        ]
        assert {sc["id"]: sc["label_set_version"] for sc in lineage["scenes"]} == {1: 2, 2: 1, 3: 2}

        # the worker killed mid-pair: its flow process finishes the work, the release appears by itself
        fix = _corrected(svc, 2, tmp_path, 2)
        assert svc.siteline("labels", "import", "2", str(fix)).returncode == 0
        _rendering(svc, "scene-2-labels-v2")
        t0 = time.monotonic()
        for pid in svc.processes("prefect worker start"):
            os.kill(pid, signal.SIGKILL)
        _until("release 3.0.0 after the worker's kill", lambda: "3.0.0" in svc.versions(), 600)
        figures["worker killed mid-pair -> 3.0.0 (s)"] = time.monotonic() - t0
        # the run publishes, then reports its state: allow the report a minute
        _until("the scene-2-labels-v2 run to complete",
               lambda: _scene_run(svc, "scene-2-labels-v2")["state_type"] == "COMPLETED", 60)  # fmt: skip

        # the worker and the flow process killed together (a machine failure): the run is marked
        # crashed when its heartbeats stop, rescheduled, and finished by the restarted worker
        fix = _corrected(svc, 1, tmp_path, 3)
        assert svc.siteline("labels", "import", "1", str(fix)).returncode == 0
        _rendering(svc, "scene-1-labels-v3")
        victim = _scene_run(svc, "scene-1-labels-v3")["id"]
        t0 = time.monotonic()
        for pid in svc.processes("prefect worker start") + svc.processes("prefect.engine"):
            os.kill(pid, signal.SIGKILL)
        # the run's own page says why within a minute: deploy/reporter.py's artifact on the run
        why = _until("the run's why-artifact", lambda: svc.artifacts(f"why-{victim}"), 180, 1.0)
        figures["worker and flow killed -> why on the run's page (s)"] = time.monotonic() - t0
        assert "no heartbeat" in why[0]["data"] and "stopped" in why[0]["data"], why[0]["data"]
        _until("release 4.0.0 after the machine failure", lambda: "4.0.0" in svc.versions(), 900, 2.0)
        figures["worker and flow killed -> 4.0.0 (s)"] = time.monotonic() - t0
        assert figures["worker and flow killed -> why on the run's page (s)"] < 60, figures
        # crash detection (heartbeats) and a slot lease that a dead holder cannot renew: minutes, not ten
        assert figures["worker and flow killed -> 4.0.0 (s)"] < 180, figures
        run = _until("the rescheduled run to complete",
                     lambda: (r := _scene_run(svc, "scene-1-labels-v3"))["state_type"] == "COMPLETED" and r, 300)  # fmt: skip
        assert run["run_count"] >= 2

        # the UI shows the release's images: the artifact page in headless Chromium loads the montage
        chromium = str(chromium_path())
        arts = httpx.post(f"{svc.api}/artifacts/filter", json={"artifacts": {"key": {"any_": ["release-demo-demo-cd"]}}},
                          timeout=30).json()  # fmt: skip
        latest = max(arts, key=lambda a: a["created"])
        page = subprocess.run(
            [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={tmp_path / 'chromium'}", "--virtual-time-budget=20000", "--dump-dom",
             f"{svc.api.removesuffix('/api')}/artifacts/artifact/{latest['id']}"],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        montage = f"{svc.preview}/releases/demo-cd/4.0.0/montage.png"
        assert "Release demo-cd 4.0.0 (published)" in page.stdout and f'src="{montage}"' in page.stdout
        got = httpx.get(montage, timeout=30)
        assert got.status_code == 200 and got.content[:8] == b"\x89PNG\r\n\x1a\n"
        # the release artifact links its browser and its pairs in 3D, which the service's preview server serves
        browse = f"{svc.preview}/browse/demo-cd/4.0.0/"
        assert (
            f'href="{browse}"' in page.stdout and f'href="{svc.preview}/3d/demo-cd/4.0.0/1/"' in page.stdout
        )
        assert httpx.get(browse, timeout=30).status_code == 200
        plan = httpx.get(f"{svc.preview}/3d/demo-cd/4.0.0/1/plan.json", timeout=120).json()
        assert plan["points"]["t1"] > 0 and plan["cameras"]
        _screenshots(svc, victim, svc.artifacts(f"why-{victim}")[0]["id"], tmp_path)
    finally:
        print("\n".join(f"{k}: {v:.0f}" for k, v in figures.items()))
        svc.stop()
