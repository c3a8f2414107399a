"""The procedural construction site and how it evolves epoch by epoch (site-local metres).

Layout: terrain 160 m x 130 m around the origin, a 120 m x 90 m fence, an excavation that deepens then
is backfilled, a building rising a floor per epoch with formwork on its top edge, a tower crane whose
jib turns, vehicles and workers that move, material piles that come and go, trees outside the fence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

import numpy as np

from siteline.errors import SynthError
from siteline.synth.primitives import Primitive

# LAS source codes understood by the default taxonomy (schema/taxonomy.default.json)
GROUND, VEG_LOW, VEG_MED, VEG_HIGH, BUILDING, NOISE = 2, 3, 4, 5, 6, 7
# LAS 1.2 point format 3 holds classes 0-31: 19 (overhead structure) and 21 (snow) as in LAS 1.4,
# site-specific codes in the reserved 24-27.
CRANE, SNOW, MATERIAL, VEHICLE, TEMPORARY, WORKER = 19, 21, 24, 25, 26, 27

TERRAIN_M = (-80.0, 80.0, -65.0, 65.0)
FENCE_M = ((-60.0, -45.0), (60.0, -45.0), (60.0, 45.0), (-60.0, 45.0))
# the sloped scene (layout "slope"): a smaller site on a 6 % / 2 % slope
SLOPE_TERRAIN_M = (-45.0, 45.0, -35.0, 35.0)
SLOPE_FENCE_M = ((-40.0, -30.0), (40.0, -30.0), (40.0, 30.0), (-40.0, 30.0))
SLOPE_GRADE = (0.06, 0.02)
SLOPE_TRENCH_M = (-30.0, -12.0, -22.6, -21.4)  # 18 m x 1.2 m, dug 1.5 m deep in odd epochs
SLOPE_TRENCH_DEPTH_M, SLOPE_TRENCH_RAMP_M = 1.5, 0.3
PIT_M = (15.0, 40.0, -35.0, -10.0)
PIT_DEPTHS_M = (2.0, 4.0, 4.0, 0.0)
BUILDING_M = (-40.0, -5.0, -15.0, 20.0)
FLOOR_M = 3.5
CRANE_BASE_M = (5.0, 28.0)
CRANE_HEIGHT_M = 42.0
SLOPE = (0.01, 0.005)
FIRST_EPOCH = datetime(2024, 11, 27, 15, 0, tzinfo=UTC)
# "site": the construction site above; "boxes": the analytic box scene (box_scene); "slope": a sloped
# site with a building, a machine and a tree that stay and a car, a stockpile, a trench, a pole and a
# fence panel that change (slope_scene)
LAYOUTS = ("site", "boxes", "slope")
BOX_MAST_M = (0.0, 5.0)
BOX_JIB_HEIGHT_M = 18.0
BOX_JIB_LENGTH_M = 24.0
EPOCH_DAYS = (0, 26, 53, 79, 105)


@dataclass(frozen=True)
class EpochSpec:
    """What one epoch looks like and its capture time (UTC)."""

    index: int
    time: datetime
    pit_depth_m: float
    floors: int
    jib_deg: float
    vehicles: tuple[tuple[float, float, float], ...]
    workers: tuple[tuple[float, float], ...]
    piles: tuple[bool, ...]
    snow: bool = False
    projection_error: bool = False

    @property
    def name(self) -> str:
        return f"e{self.index:02d}_{self.time:%Y%m%d}"


@dataclass
class SiteModel:
    """A seeded site; ``epochs`` evolve it. ``snow_epochs``: accumulated and airborne snow;
    ``projection_error_epochs``: crane colour smeared onto the ground below its jib."""

    seed: int = 0
    n_epochs: int = 4
    snow_epochs: tuple[int, ...] = (2,)
    projection_error_epochs: tuple[int, ...] = (1,)
    layout: str = "site"
    epochs: list[EpochSpec] = field(init=False)

    def __post_init__(self) -> None:
        if not 1 <= self.n_epochs <= 12:
            raise SynthError(f"epochs must be between 1 and 12, got {self.n_epochs}.")
        if self.layout not in LAYOUTS:
            raise SynthError(f"layout {self.layout!r}: use one of {', '.join(LAYOUTS)}.")
        rng = np.random.default_rng(self.seed)
        pile_sites = 4
        self.epochs = []
        for e in range(self.n_epochs):
            day = EPOCH_DAYS[e] if e < len(EPOCH_DAYS) else EPOCH_DAYS[-1] + 26 * (e - len(EPOCH_DAYS) + 1)
            vehicles = tuple(
                (float(rng.uniform(-50, 50)), float(rng.uniform(-40, -22)), float(rng.uniform(0, math.pi)))
                for _ in range(3)
            )
            workers = tuple((float(rng.uniform(-55, 55)), float(rng.uniform(-40, 40))) for _ in range(6))
            piles = tuple(bool(rng.random() < 0.6) for _ in range(pile_sites))
            self.epochs.append(
                EpochSpec(
                    index=e,
                    time=FIRST_EPOCH + timedelta(days=day, minutes=int(rng.integers(0, 120))),
                    pit_depth_m=PIT_DEPTHS_M[e] if e < len(PIT_DEPTHS_M) else 0.0,
                    floors=min(e, 6),
                    jib_deg=float((37.0 + 71.0 * e + rng.uniform(-10, 10)) % 360.0),
                    vehicles=vehicles,
                    workers=workers,
                    piles=piles,
                    snow=e in self.snow_epochs,
                    projection_error=e in self.projection_error_epochs,
                )
            )

    @property
    def terrain_m(self) -> tuple[float, float, float, float]:
        """The terrain's rectangle (x0, x1, y0, y1), site-local metres."""
        return SLOPE_TERRAIN_M if self.layout == "slope" else TERRAIN_M

    @property
    def fence_m(self) -> tuple[tuple[float, float], ...]:
        """The site fence (a ring without its closing vertex), site-local metres."""
        return SLOPE_FENCE_M if self.layout == "slope" else FENCE_M

    def primitives(self, e: int) -> list[Primitive]:
        """Every surface of epoch ``e``."""
        if self.layout == "boxes":
            return box_scene(e)
        if self.layout == "slope":
            return slope_scene(e)
        ep = self.epochs[e]
        out: list[Primitive] = []
        x0, x1, y0, y1 = TERRAIN_M
        pit = (*PIT_M, ep.pit_depth_m)
        out.append(
            Primitive(
                "terrain:open",
                "v1",
                1,
                GROUND,
                "terrain",
                (TERRAIN_M, SLOPE, None, PIT_M),
                (120, 100, 80),
                upward=True,
            )
        )
        out.append(
            Primitive(
                "terrain:pit",
                f"depth={ep.pit_depth_m:g}",
                2,
                GROUND,
                "terrain",
                (PIT_M, SLOPE, pit, None),
                (110, 85, 60),
                upward=True,
            )
        )
        out.extend(self._building(ep))
        out.extend(self._crane(ep))
        out.extend(self._fence())
        out.extend(self._trees())
        for i, (vx, vy, yaw) in enumerate(ep.vehicles):
            z = float(SLOPE[0] * vx + SLOPE[1] * vy)
            sig = f"{vx:.3f},{vy:.3f},{yaw:.3f}"
            out.append(
                Primitive(
                    f"vehicle:{i}:body",
                    sig,
                    300 + i,
                    VEHICLE,
                    "box",
                    ((vx, vy, z), (8.0, 3.0, 2.5), yaw),
                    (240, 200, 20),
                    upward=True,
                )
            )
            cab = (vx + 3.0 * math.cos(yaw), vy + 3.0 * math.sin(yaw), z + 2.5)
            out.append(
                Primitive(
                    f"vehicle:{i}:cab",
                    sig,
                    300 + i,
                    VEHICLE,
                    "box",
                    (cab, (2.0, 2.6, 1.5), yaw),
                    (60, 60, 70),
                    upward=True,
                )
            )
        for i, (wx, wy) in enumerate(ep.workers):
            z = float(SLOPE[0] * wx + SLOPE[1] * wy)
            out.append(
                Primitive(
                    f"worker:{i}",
                    f"{wx:.3f},{wy:.3f}",
                    400 + i,
                    WORKER,
                    "cylinder",
                    (wx, wy, z, 0.3, 1.8),
                    (255, 120, 0),
                )
            )
        for i, present in enumerate(ep.piles):
            if present:
                px, py = -50.0 + 22.0 * i, 35.0
                r, h = 3.0 + 0.5 * i, 2.0 + 0.3 * i
                z = float(SLOPE[0] * px + SLOPE[1] * py)
                out.append(
                    Primitive(
                        f"pile:{i}",
                        "v1",
                        500 + i,
                        MATERIAL,
                        "cone",
                        (px, py, z, r, h),
                        (150 + 20 * i, 140, 120),
                        upward=True,
                    )
                )
        return out

    def _building(self, ep: EpochSpec) -> list[Primitive]:
        bx0, bx1, by0, by1 = BUILDING_M
        base = float(SLOPE[0] * (bx0 + bx1) / 2 + SLOPE[1] * (by0 + by1) / 2)
        out = [
            Primitive(
                "building:foundation",
                "v1",
                100,
                BUILDING,
                "box",
                (((bx0 + bx1) / 2, (by0 + by1) / 2, base), (bx1 - bx0, by1 - by0, 0.5), 0.0),
                (170, 170, 165),
                upward=True,
            )
        ]
        top = base + 0.5
        for f in range(ep.floors):
            zf = base + 0.5 + f * FLOOR_M
            for i, cx in enumerate(np.linspace(bx0 + 1, bx1 - 1, 5)):
                for j, cy in enumerate(np.linspace(by0 + 1, by1 - 1, 5)):
                    out.append(
                        Primitive(
                            f"building:column:{f}:{i}:{j}",
                            "v1",
                            100,
                            BUILDING,
                            "cylinder",
                            (float(cx), float(cy), zf, 0.3, FLOOR_M - 0.3),
                            (185, 185, 180),
                        )
                    )
            out.append(
                Primitive(
                    f"building:slab:{f}",
                    "v1",
                    100,
                    BUILDING,
                    "box",
                    (
                        ((bx0 + bx1) / 2, (by0 + by1) / 2, zf + FLOOR_M - 0.3),
                        (bx1 - bx0, by1 - by0, 0.3),
                        0.0,
                    ),
                    (175, 175, 170),
                    upward=True,
                )
            )
            if f < ep.floors - 1:  # walls close the floors below the top one
                for side, (o, u) in enumerate(
                    (((bx0, by0), (bx1 - bx0, 0.0)), ((bx0, by1), (bx1 - bx0, 0.0)))
                ):
                    out.append(
                        Primitive(
                            f"building:wall:{f}:{side}",
                            "v1",
                            100,
                            BUILDING,
                            "quad",
                            ((o[0], o[1], zf), (u[0], u[1], 0.0), (0.0, 0.0, FLOOR_M - 0.3)),
                            (200, 195, 185),
                        )
                    )
            top = zf + FLOOR_M
        # formwork stands on the current top edge and moves up as floors are added
        for side, (o, u) in enumerate((((bx0, by0), (bx1 - bx0, 0.0)), ((bx1, by0), (0.0, by1 - by0)))):
            out.append(
                Primitive(
                    f"temporary:formwork:{side}",
                    f"top={top:.2f}",
                    600 + side,
                    TEMPORARY,
                    "quad",
                    ((o[0], o[1], top), (u[0], u[1], 0.0), (0.0, 0.0, 1.2)),
                    (60, 110, 200),
                )
            )
        return out

    def _crane(self, ep: EpochSpec) -> list[Primitive]:
        cx, cy = CRANE_BASE_M
        base = float(SLOPE[0] * cx + SLOPE[1] * cy)
        a = math.radians(ep.jib_deg)
        d = np.array([math.cos(a), math.sin(a)])
        jib_c = np.array([cx, cy]) + d * 25.0
        cj_c = np.array([cx, cy]) - d * 8.0
        z = base + CRANE_HEIGHT_M
        sig = f"jib={ep.jib_deg:.3f}"
        return [
            Primitive(
                "crane:mast",
                "v1",
                200,
                CRANE,
                "box",
                ((cx, cy, base), (2.0, 2.0, CRANE_HEIGHT_M), 0.0),
                (220, 40, 30),
            ),
            Primitive(
                "crane:jib",
                sig,
                200,
                CRANE,
                "box",
                ((float(jib_c[0]), float(jib_c[1]), z), (50.0, 1.6, 1.6), a),
                (230, 50, 35),
                upward=True,
            ),
            Primitive(
                "crane:counterjib",
                sig,
                200,
                CRANE,
                "box",
                ((float(cj_c[0]), float(cj_c[1]), z), (16.0, 2.5, 2.0), a),
                (120, 120, 120),
                upward=True,
            ),
        ]

    def _fence(self) -> list[Primitive]:
        out = []
        ring = list(FENCE_M) + [FENCE_M[0]]
        for i in range(len(FENCE_M)):
            (ax, ay), (bx, by) = ring[i], ring[i + 1]
            z = float(SLOPE[0] * ax + SLOPE[1] * ay)
            out.append(
                Primitive(
                    f"temporary:fence:{i}",
                    "v1",
                    700,
                    TEMPORARY,
                    "quad",
                    ((ax, ay, z), (bx - ax, by - ay, 0.0), (0.0, 0.0, 2.0)),
                    (90, 90, 100),
                )
            )
        return out

    def _trees(self) -> list[Primitive]:
        rng = np.random.default_rng(self.seed + 1000)
        out = []
        for i in range(14):
            side = i % 4
            if side == 0:
                x, y = rng.uniform(-75, 75), rng.uniform(50, 62)
            elif side == 1:
                x, y = rng.uniform(-75, 75), rng.uniform(-62, -50)
            elif side == 2:
                x, y = rng.uniform(-78, -66), rng.uniform(-40, 40)
            else:
                x, y = rng.uniform(66, 78), rng.uniform(-40, 40)
            z = float(SLOPE[0] * x + SLOPE[1] * y)
            h = float(rng.uniform(5, 9))
            r = float(rng.uniform(2, 3.5))
            out.append(
                Primitive(
                    f"tree:{i}:trunk",
                    "v1",
                    800 + i,
                    VEG_MED,
                    "cylinder",
                    (float(x), float(y), z, 0.25, h - r),
                    (90, 60, 40),
                )
            )
            out.append(
                Primitive(
                    f"tree:{i}:crown",
                    "v1",
                    800 + i,
                    VEG_HIGH,
                    "canopy",
                    (float(x), float(y), z + h - r * 0.5, r, CANOPY_DEPTH_M),
                    (40, 120, 45),
                    upward=True,
                )
            )
        # one tree inside the fence, which stays: its leaves are other leaves in every scan
        out.extend(tree("tree:yard", 814, (45.0, 35.0), float(SLOPE[0] * 45.0 + SLOPE[1] * 35.0), 8.0, 3.0))
        return out

    def jib_ground_footprint(self, e: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Centre (2,), direction (2,) and length (m) of the jib projected onto the ground (the sloped
        scene has no crane: a zero-length footprint)."""
        if self.layout == "slope":
            return np.zeros(2), np.array([1.0, 0.0]), 0.0
        if self.layout == "boxes":
            a = math.radians(30.0 + 60.0 * e)
            d = np.array([math.cos(a), math.sin(a)])
            return np.array(BOX_MAST_M) + d * BOX_JIB_LENGTH_M / 2, d, BOX_JIB_LENGTH_M
        a = math.radians(self.epochs[e].jib_deg)
        d = np.array([math.cos(a), math.sin(a)])
        return np.array(CRANE_BASE_M) + d * 25.0, d, 50.0


# mean depth (metres) of a canopy's returns under its crown's surface
CANOPY_DEPTH_M = 0.3


def tree(
    key: str, object_id: int, xy: tuple[float, float], z: float, height_m: float, crown_m: float
) -> list[Primitive]:
    """A trunk and a canopy crown of radius ``crown_m`` topping out at ``height_m`` above ``z``."""
    x, y = xy
    return [
        Primitive(f"{key}:trunk", "v1", object_id, VEG_MED, "cylinder", (x, y, z, 0.25, height_m - crown_m), (90, 60, 40)),
        Primitive(f"{key}:crown", "v1", object_id, VEG_HIGH, "canopy", (x, y, z + height_m - crown_m, crown_m, CANOPY_DEPTH_M),
                  (40, 120, 45), True),
    ]  # fmt: skip


def box_scene(e: int) -> list[Primitive]:
    """Epoch ``e`` of the analytic box scene: boxes on flat ground, every change known in closed form.

    Kept in every epoch: flat ground over the terrain, a shed (6 x 4 x 3 m) and a mast (1.5 m square,
    18 m). A 24 m jib (1 m square) on the mast turns 60 degrees an epoch; a container (12 x 2.5 x
    2.6 m) stands in even epochs and a block (4 x 4 x 3 m) in odd ones; a pole (0.4 m wide, 4 m)
    moves 6 m east an epoch: a thin beam that turns and a thin post that moves. A tree (8 m, a 3 m
    crown) stays, its leaves other leaves in every scan."""
    mx, my = BOX_MAST_M
    a = math.radians(30.0 + 60.0 * e)
    jib_c = (
        mx + math.cos(a) * BOX_JIB_LENGTH_M / 2,
        my + math.sin(a) * BOX_JIB_LENGTH_M / 2,
        BOX_JIB_HEIGHT_M,
    )
    pole_x = -20.0 + 6.0 * (e % 4)
    out = [
        Primitive("ground", "v1", 1, GROUND, "terrain", (TERRAIN_M, (0.0, 0.0), None, None), (120, 100, 80), True),
        Primitive("shed", "v1", 10, TEMPORARY, "box", ((25.0, 22.0, 0.0), (6.0, 4.0, 3.0), 0.3), (90, 110, 160), True),
        Primitive("mast", "v1", 20, CRANE, "box", ((mx, my, 0.0), (1.5, 1.5, BOX_JIB_HEIGHT_M), 0.0), (220, 40, 30)),
        Primitive("jib", f"{math.degrees(a) % 360:.1f}", 21, CRANE, "box", (jib_c, (BOX_JIB_LENGTH_M, 1.0, 1.0), a),
                  (230, 50, 35), True),
        Primitive("pole", f"x={pole_x:g}", 30, TEMPORARY, "cylinder", (pole_x, -30.0, 0.0, 0.2, 4.0), (250, 200, 30)),
        *tree("tree", 60, (-40.0, -10.0), 0.0, 8.0, 3.0),
    ]  # fmt: skip
    if e % 2 == 0:
        out.append(
            Primitive("container", "v1", 40, MATERIAL, "box", ((-30.0, 20.0, 0.0), (12.0, 2.5, 2.6), 0.0), (40, 120, 160), True)
        )  # fmt: skip
    else:
        out.append(
            Primitive("block", "v1", 50, BUILDING, "box", ((30.0, -20.0, 0.0), (4.0, 4.0, 3.0), 0.0), (170, 170, 165), True)
        )  # fmt: skip
    return out


def _slope_z(x: float, y: float) -> float:
    return float(SLOPE_GRADE[0] * x + SLOPE_GRADE[1] * y)


def _on_slope(
    xy: tuple[float, float], size: tuple[float, float, float], yaw: float
) -> tuple[float, float, float]:
    """A box's base centre standing on the slope: its base at the lowest ground under its footprint
    (the uphill part of its sides is buried, as a building's is)."""
    x, y = xy
    c, s = math.cos(yaw), math.sin(yaw)
    corners = [(x + a * c * size[0] / 2 - b * s * size[1] / 2, y + a * s * size[0] / 2 + b * c * size[1] / 2)
               for a in (-1, 1) for b in (-1, 1)]  # fmt: skip
    return (x, y, min(_slope_z(*p) for p in corners))


def slope_scene(e: int) -> list[Primitive]:
    """Epoch ``e`` of the sloped scene (even epochs: before, odd: after), every change known in closed form.

    Stay: the ground on a 6 % / 2 % slope, an 8 m building (14 x 10 m), an excavator, a 9 m tree (its
    leaves other leaves in every scan) and a fence of five 5 cm panels. Change: a car moves 6 m east,
    a stockpile grows (3 -> 3.8 m radius, 2 -> 2.8 m high), a trench (18 x 1.2 m) is dug 1.5 m deep, a
    6 m pole (0.2 m wide) is put up and the fence's middle panel is taken away."""
    after = e % 2 == 1
    x0, x1, y0, y1 = SLOPE_TERRAIN_M
    trench = (*SLOPE_TRENCH_M, SLOPE_TRENCH_DEPTH_M if after else 0.0, SLOPE_TRENCH_RAMP_M)
    car_x = 1.0 if after else -5.0
    pile_r, pile_h = (3.8, 2.8) if after else (3.0, 2.0)
    bsize, byaw = (14.0, 10.0, 8.0), 0.15
    out = [
        Primitive("ground", "v1", 1, GROUND, "terrain", (SLOPE_TERRAIN_M, SLOPE_GRADE, None, SLOPE_TRENCH_M), (120, 100, 80), True),
        Primitive("trench", f"depth={trench[4]:g}", 2, GROUND, "terrain", (SLOPE_TRENCH_M, SLOPE_GRADE, trench, None), (110, 85, 60), True),
        Primitive("building", "v1", 100, BUILDING, "box", (_on_slope((-18.0, 8.0), bsize, byaw), bsize, byaw), (175, 170, 160), True),
        Primitive("excavator:body", "v1", 310, VEHICLE, "box", (_on_slope((8.0, -10.0), (4.0, 2.6, 1.4), 0.6), (4.0, 2.6, 1.4), 0.6),
                  (240, 190, 20), True),
        Primitive("excavator:cab", "v1", 310, VEHICLE, "box",
                  ((8.0, -10.0, _on_slope((8.0, -10.0), (4.0, 2.6, 1.4), 0.6)[2] + 1.4), (1.8, 2.2, 1.6), 0.6), (60, 60, 70), True),
        Primitive("excavator:arm", "v1", 310, VEHICLE, "box",
                  ((8.0 + 3.2 * math.cos(0.6), -10.0 + 3.2 * math.sin(0.6), _slope_z(8.0, -10.0) + 1.8), (3.6, 0.5, 0.6), 0.6),
                  (240, 190, 20), True),
        *tree("tree", 800, (24.0, 14.0), _slope_z(24.0, 14.0) - 0.1, 9.0, 3.0),
        Primitive("car", f"x={car_x:g}", 320, VEHICLE, "box", (_on_slope((car_x, -18.0), (4.5, 1.8, 1.5), 0.0), (4.5, 1.8, 1.5), 0.0),
                  (200, 30, 40), True),
        Primitive("stockpile", f"r={pile_r:g},h={pile_h:g}", 500, MATERIAL, "cone",
                  (25.0, -14.0, _slope_z(25.0, -14.0) - 0.2, pile_r, pile_h), (150, 140, 120), True),
    ]  # fmt: skip
    if after:
        out.append(
            Primitive("pole", "v1", 700, TEMPORARY, "cylinder", (8.0, 18.0, _slope_z(8.0, 18.0) - 0.1, 0.1, 6.0), (250, 200, 30))
        )  # fmt: skip
    for i in range(5):
        if after and i == 2:
            continue
        cx = -20.0 + 2.5 * i + 1.25
        size = (2.5, 0.05, 2.0)
        out.append(
            Primitive(f"fence:{i}", "v1", 710 + i, TEMPORARY, "box", (_on_slope((cx, -26.0), size, 0.0), size, 0.0),
                      (90, 90, 100))
        )  # fmt: skip
    return out
