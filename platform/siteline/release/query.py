"""Comparing two versions of a release: their catalog rows and manifests."""

from __future__ import annotations

from pathlib import Path

from sqlalchemy.orm import Session

from siteline.catalog.releases import get_release
from siteline.records.enums import SPLITS
from siteline.records.pairs import ChangeLabels
from siteline.release.manifest import read_manifest
from siteline.schema import JSON


def _flat(d: JSON, prefix: str = "") -> dict[str, JSON]:
    """``d`` with its nested objects' keys joined by dots (``a.b``)."""
    if isinstance(d, dict):
        out: dict[str, JSON] = {}
        for k, v in d.items():
            out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    return {prefix: d}


def diff_releases(session: Session, name: str, v1: str, v2: str) -> dict[str, object]:
    """Pairs, parameters, label sets (each scene's label-set version; each pair's change labels) and
    files that differ between two versions."""
    a, b = get_release(session, name, v1), get_release(session, name, v2)
    ma, mb = read_manifest(Path(str(a.root_uri))), read_manifest(Path(str(b.root_uri)))
    pa = {p["id"]: p for p in ma.lineage["pairs"]}
    pb = {p["id"]: p for p in mb.lineage["pairs"]}
    fa, fb = ma.files, mb.files
    flat_a, flat_b = _flat(ma.lineage["parameters"]), _flat(mb.lineage["parameters"])
    pair_labels = {
        pid: {"radius_m": [pa[pid]["radius_m"], pb[pid]["radius_m"]]}
        for pid in sorted(set(pa) & set(pb))
        if pa[pid]["radius_m"] != pb[pid]["radius_m"]
        or ChangeLabels.from_dict(pa[pid]["labels"]).checksum
        != ChangeLabels.from_dict(pb[pid]["labels"]).checksum
    }
    # a lineage written before label sets were versioned used version 1 of every scene
    sa_ = {sc["id"]: sc for sc in ma.lineage["scenes"]}
    sb_ = {sc["id"]: sc for sc in mb.lineage["scenes"]}
    scene_labels = {
        sid: {
            "version": [sa_[sid].get("label_set_version", 1), sb_[sid].get("label_set_version", 1)],
            "source": [sa_[sid].get("label_set_source"), sb_[sid].get("label_set_source")],
        }
        for sid in sorted(set(sa_) & set(sb_))
        if sa_[sid].get("label_set_version", 1) != sb_[sid].get("label_set_version", 1)
    }
    return {
        "name": name,
        "from": v1,
        "to": v2,
        # why the later version exists (its bump: new items only -> minor, an item changed -> major)
        "why": mb.lineage.get("version_reason"),
        "pairs": {"added": sorted(set(pb) - set(pa)), "removed": sorted(set(pa) - set(pb))},
        "parameters": {
            k: [flat_a.get(k), flat_b.get(k)]
            for k in sorted(set(flat_a) | set(flat_b))
            if flat_a.get(k) != flat_b.get(k)
        },
        "label_sets": {"scenes": scene_labels, "pairs": pair_labels},
        "splits": {
            s: [list(ma.splits[s]), list(mb.splits[s])] for s in SPLITS if ma.splits[s] != mb.splits[s]
        },
        "files": {
            "added": sorted(set(fb) - set(fa)),
            "removed": sorted(set(fa) - set(fb)),
            "changed": sorted(p for p in set(fa) & set(fb) if fa[p] != fb[p]),
        },
    }
