"""Procedural pedestrians: an articulated figure (skeleton + one closed mesh per body segment) in a pose.

The skeleton's proportions are fractions of the standing height (adult anthropometric tables, a child
with a bigger head and shorter legs); joint positions come from a pose: ``walking`` (legs in stride,
knee bent in swing, arms counter-swinging at a random gait phase), ``standing`` (small asymmetric
stance) or *riding* (seated; hands and feet placed by two-bone inverse kinematics, see
:func:`rider_parts`).  Each segment (torso, neck, head, hair, upper/lower arms, hands, thighs, shins,
shoes) is a closed loft of ellipses; clothing is a material per segment (top, trousers / shorts /
skirt, shoes, skin, hair, optional bag, helmet for motorcyclists).  Object frame: x front, y left, z up,
metres, origin at the bottom centre of the box, soles on z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .asset import Asset, Material
from .class_sizes import read_class_sizes
from .mesh_parts import MeshPart, merge_parts, target_wlh
from .procedural import srgb_to_linear
from .revolve import capsule, ellipse_rings, ellipsoid, loft, rot_y, with_material
from .validate import validate_asset

# Material slots of a figure (indices into :func:`figure_materials`' table).
SKIN, TOP, BOTTOM, SHOES, HAIR, BAG, HELMET = range(7)

_VARIANTS = ("adult", "child")
_POSES = ("walking", "standing")
_CATEGORY = {"adult": "human.pedestrian.adult", "child": "human.pedestrian.child"}
_ATTRIBUTE = {"walking": "pedestrian.moving", "standing": "pedestrian.standing"}

# sRGB swatches: skin tones light -> dark, hair, clothing.
_SKIN = ("F5D7C4", "EBC0A0", "DDA987", "C98F6B", "B07452", "8F5A3C", "6E4129", "4E2C1B")
_HAIR = ("0E0B0A", "1F1510", "3B2619", "5E4030", "8A6A45", "B89A6A", "9A9690", "6A2E1C")
_TOPS = ("111113", "1C2438", "3A3D44", "7A7C80", "D8D8D4", "EFEFEA", "8A1C1E", "2D4A2E", "3F5E8C", "B8A58A",
         "5A3D2B", "C45A2A", "6B4E7A", "2E6E73", "D9B43A", "8FA6BD")
_BOTTOMS = ("1B2536", "2C3E5C", "4A6385", "121214", "3A3A3E", "7D6F58", "A89B80", "4B4F3A", "5B4636")
_SHOES = ("101010", "E8E8E4", "4A3222", "6E6E70", "2A2A30", "8A6A4A")
_BAGS = ("151515", "2B3340", "5A4632", "6E2424", "3E4A3A", "8A7A66")


def procedural_pedestrian_variants() -> tuple[str, ...]:
    """Names of the figures :func:`procedural_pedestrian` builds (``adult``, ``child``)."""
    return _VARIANTS


def pedestrian_poses() -> tuple[str, ...]:
    """Poses :func:`procedural_pedestrian` accepts (``walking``, ``standing``)."""
    return _POSES


# ----------------------------------------------------------------------------- body proportions


@dataclass(frozen=True)
class Body:
    """Segment lengths and radii (metres) of a figure of standing height ``height``.

    Heights are of the standing figure above the soles; ``*_r`` are segment radii at their two ends.
    """

    height: float
    head_h: float  # chin to crown
    head_w: float  # ear to ear
    head_d: float  # nose to back
    neck_len: float
    neck_r: float
    shoulder_z: float
    shoulder_half: float  # centre to the shoulder joint
    hip_z: float
    hip_half: float
    crotch_z: float
    upper_arm: float
    forearm: float
    hand_len: float
    arm_r: tuple[float, float]
    forearm_r: tuple[float, float]
    thigh: float
    shin: float
    thigh_r: tuple[float, float]
    shin_r: tuple[float, float]
    ankle_h: float
    foot_len: float
    foot_w: float
    girth: float  # torso width/depth multiplier (build)


def body_for(height: float, child: bool, rng: np.random.Generator) -> Body:
    """A :class:`Body` of ``height`` m with randomised build (7 draws from ``rng``).

    Adult fractions of height follow standard anthropometry (shoulder joint 0.818 H, hip joint 0.53 H,
    knee 0.285 H, head 0.13 H, biacromial width 0.259 H); a child's head is 0.16-0.21 H and the rest of
    the body is an adult's of the remaining height.
    """
    u = rng.random(7)
    H = float(height)
    if child:
        head_frac = float(np.clip(0.165 + 0.10 * (1.30 - H) / 0.45, 0.15, 0.21))
    else:
        head_frac = 0.128 + 0.008 * u[0]
    head_h = head_frac * H
    # Adult body below the chin (0.87 of the adult height) stretched to H - head - a short neck.
    neck_frac = 0.035 if not child else 0.03
    B = (H - head_h - neck_frac * H) / 0.835  # "adult height" the trunk and limbs are taken from
    girth = 0.92 + 0.22 * u[1]
    leg_scale = 0.97 + 0.06 * u[2] if not child else 0.93 + 0.04 * u[2]
    hip_z = 0.53 * B * leg_scale
    shoulder_z = H - head_h - neck_frac * H - 0.017 * B
    limb = 0.95 + 0.1 * u[3]
    knee_z = hip_z * 0.285 / 0.53
    ankle_h = 0.039 * B
    return Body(
        height=H, head_h=head_h, head_w=head_h * (0.66 if not child else 0.72) * (0.97 + 0.06 * u[4]),
        head_d=head_h * (0.82 if not child else 0.86), neck_len=neck_frac * H + 0.017 * B, neck_r=0.030 * B,
        shoulder_z=shoulder_z, shoulder_half=0.1295 * B * (0.95 + 0.1 * u[5]) * (0.9 if child else 1.0),
        hip_z=hip_z, hip_half=0.05 * B * girth, crotch_z=hip_z - 0.055 * B,
        upper_arm=0.186 * B * limb, forearm=0.146 * B * limb, hand_len=0.105 * B,
        arm_r=(0.030 * B * girth, 0.024 * B * girth), forearm_r=(0.022 * B * girth, 0.016 * B),
        thigh=hip_z - knee_z, shin=knee_z - ankle_h,
        thigh_r=(0.052 * B * girth, 0.033 * B), shin_r=(0.037 * B, 0.021 * B), ankle_h=ankle_h,
        foot_len=0.152 * B * (0.96 + 0.08 * u[6]), foot_w=0.055 * B, girth=girth,
    )


# ----------------------------------------------------------------------------- poses (joint positions)


@dataclass(frozen=True)
class Pose:
    """Joint angles (radians) of a standing or walking figure.

    ``hip`` / ``knee`` / ``shoulder`` / ``elbow``: (left, right) flexion (forward positive; knee flexion
    bends the shin back); ``abduct``: arm angle out to the side; ``stance``: extra half-distance between
    the feet (m); ``lean``: trunk lean forward; ``turn``: the head's yaw.
    """

    hip: tuple[float, float]
    knee: tuple[float, float]
    shoulder: tuple[float, float]
    elbow: tuple[float, float]
    abduct: float
    stance: float
    lean: float
    turn: float


def walking_pose(rng: np.random.Generator, gain: float = 1.0) -> Pose:
    """A walking pose at a random gait phase (6 draws); ``gain`` scales the stride and the arm swing."""
    u = rng.random(6)
    phase = 2 * np.pi * u[0]
    A = np.radians(17 + 9 * u[1]) * gain
    Bs = np.radians(10 + 14 * u[2]) * gain
    hip, knee, sh, el = [], [], [], []
    for ph in (phase, phase + np.pi):
        hip.append(A * np.sin(ph))
        knee.append(np.radians(4) + np.radians(58) * max(0.0, np.cos(ph)) ** 1.5)
        sh.append(-Bs * np.sin(ph))
        el.append(np.radians(12 + 10 * u[3]) + max(0.0, -np.sin(ph)) * Bs * 0.8)
    return Pose(tuple(hip), tuple(knee), tuple(sh), tuple(el), abduct=np.radians(5 + 4 * u[4]), stance=0.0,
                lean=np.radians(2 + 4 * u[5]), turn=0.0)


def standing_pose(rng: np.random.Generator, gain: float = 1.0) -> Pose:
    """A relaxed standing pose with a small asymmetry (6 draws); ``gain`` scales the stagger of the feet."""
    u = rng.random(6)
    side = 1 if u[0] < 0.5 else 0
    stag = np.radians(4 + 6 * u[1]) * gain
    hip = [-0.35 * stag, -0.35 * stag]
    hip[side] = stag
    knee = [np.radians(2), np.radians(2)]
    knee[side] = np.radians(4 + 8 * u[2])
    sh = (np.radians(-4 + 10 * u[3]), np.radians(-4 + 10 * u[4]))
    el = (np.radians(8 + 14 * u[3]), np.radians(8 + 14 * u[4]))
    return Pose(tuple(hip), tuple(knee), sh, el, abduct=np.radians(6 + 4 * u[5]), stance=0.02 + 0.03 * u[5],
                lean=np.radians(1), turn=np.radians(-15 + 30 * u[2]))


def _limb_dir(flex: float, abduct: float, side: float) -> np.ndarray:
    """Unit direction of a limb hanging down, turned forward by ``flex`` and out to ``side`` by ``abduct``."""
    return np.array([np.sin(flex) * np.cos(abduct), side * np.sin(abduct), -np.cos(flex) * np.cos(abduct)])


def standing_joints(b: Body, p: Pose) -> dict[str, np.ndarray]:
    """Joint positions (object frame, before the figure is set on the ground) of a standing/walking pose."""
    J: dict[str, np.ndarray] = {}
    pelvis = np.array([0.0, 0.0, b.hip_z])
    J["pelvis"] = pelvis
    trunk = np.array([np.sin(p.lean), 0.0, np.cos(p.lean)])
    J["trunk"] = trunk
    J["neck"] = pelvis + (b.shoulder_z - b.hip_z + 0.02 * b.height) * trunk
    for i, (side, s) in enumerate((("l", 1.0), ("r", -1.0))):
        hipj = pelvis + np.array([0.0, s * (b.hip_half + p.stance), 0.0])
        tdir = _limb_dir(p.hip[i], np.radians(1.5), s)
        knee = hipj + b.thigh * tdir
        sdir = _limb_dir(p.hip[i] - p.knee[i], np.radians(1.0), s)
        ankle = knee + b.shin * sdir
        J[f"hip_{side}"], J[f"knee_{side}"], J[f"ankle_{side}"] = hipj, knee, ankle
        J[f"toe_{side}"] = np.array([1.0, 0.12 * s, 0.0]) / np.hypot(1.0, 0.12)
        # the shoulder joint sits a little below and inside the top of the shoulder
        sh = (pelvis + (b.shoulder_z - b.hip_z - 0.022 * b.height) * trunk
              + np.array([0.0, 0.94 * s * b.shoulder_half, 0.0]))
        adir = _limb_dir(p.shoulder[i], p.abduct, s)
        elbow = sh + b.upper_arm * adir
        fdir = _limb_dir(p.shoulder[i] + p.elbow[i], p.abduct * 0.6, s)
        J[f"shoulder_{side}"], J[f"elbow_{side}"], J[f"wrist_{side}"] = sh, elbow, elbow + b.forearm * fdir
    J["head_yaw"] = np.array([p.turn, 0.0, 0.0])
    return J


def _two_bone(root: np.ndarray, target: np.ndarray, l1: float, l2: float, bend: np.ndarray) -> np.ndarray:
    """The middle joint of a two-bone chain root -> target (lengths l1, l2), bending towards ``bend``."""
    d = target - root
    dist = float(np.linalg.norm(d))
    dist_c = float(np.clip(dist, abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6))
    e = d / max(dist, 1e-9)
    a = (l1 * l1 - l2 * l2 + dist_c * dist_c) / (2 * dist_c)
    h = np.sqrt(max(l1 * l1 - a * a, 0.0))
    n = bend - e * (bend @ e)
    n /= max(np.linalg.norm(n), 1e-9)
    return root + a * e + h * n


def riding_joints(b: Body, seat: np.ndarray, hands: np.ndarray, feet: np.ndarray,
                  look_up: float = 0.0) -> dict[str, np.ndarray]:
    """Joint positions of a seated rider: pelvis on ``seat`` (3,), wrists at ``hands`` (2, 3) (left,
    right), the balls of the feet on ``feet`` (2, 3); the trunk leans forward until the arms reach."""
    J: dict[str, np.ndarray] = {}
    pelvis = np.asarray(seat, dtype=np.float64) + np.array([0.0, 0.0, 0.06 * b.height])
    J["pelvis"] = pelvis
    hands = np.asarray(hands, dtype=np.float64)
    feet = np.asarray(feet, dtype=np.float64)
    trunk_len = b.shoulder_z - b.hip_z
    reach = 0.88 * (b.upper_arm + b.forearm)
    lean = np.radians(np.arange(0.0, 75.0, 1.0))
    sh = pelvis[None, :] + trunk_len * np.stack([np.sin(lean), 0 * lean, np.cos(lean)], 1)
    mid = hands.mean(axis=0)
    half = np.array([0.0, b.shoulder_half, 0.0])
    lateral = abs(hands[0, 1] - hands[1, 1]) / 2 - b.shoulder_half  # hands outside (+) or inside the shoulders
    in_plane = np.sqrt(max(reach ** 2 - lateral ** 2, (0.3 * reach) ** 2))  # shoulder -> hand in the x-z plane
    err = np.abs(np.linalg.norm((mid[None] - sh)[:, [0, 2]], axis=1) - in_plane)
    k = int(np.argmin(err))
    trunk = np.array([np.sin(lean[k]), 0.0, np.cos(lean[k])])
    J["trunk"] = trunk
    J["neck"] = pelvis + (trunk_len + 0.02 * b.height) * trunk
    for i, (side, s) in enumerate((("l", 1.0), ("r", -1.0))):
        hipj = pelvis + np.array([0.0, s * b.hip_half, 0.0])
        toe = np.array([1.0, 0.0, 0.0])
        ankle = feet[i] + np.array([-0.25 * b.foot_len, 0.0, b.ankle_h * 0.9])
        knee = _two_bone(hipj, ankle, b.thigh, b.shin, np.array([1.0, 0.25 * s, 0.6]))
        ankle = knee + b.shin * (ankle - knee) / np.linalg.norm(ankle - knee)
        J[f"hip_{side}"], J[f"knee_{side}"], J[f"ankle_{side}"], J[f"toe_{side}"] = hipj, knee, ankle, toe
        shj = pelvis + (trunk_len - 0.022 * b.height) * trunk + 0.94 * s * half
        wrist = hands[i] - np.array([0.02 * b.height, 0.0, 0.0])
        elbow = _two_bone(shj, wrist, b.upper_arm, b.forearm, np.array([-0.3, 0.6 * s, -1.0]))
        wrist = elbow + b.forearm * (wrist - elbow) / np.linalg.norm(wrist - elbow)
        J[f"shoulder_{side}"], J[f"elbow_{side}"], J[f"wrist_{side}"] = shj, elbow, wrist
    J["head_yaw"] = np.array([0.0, look_up, 0.0])
    return J


# ----------------------------------------------------------------------------- outfit and materials


@dataclass(frozen=True)
class Outfit:
    """What the figure wears: ``sleeves`` long/short, ``bottom`` trousers/shorts/skirt, ``bag``
    none/backpack/shoulder, ``hair`` short/long/none, ``helmet``."""

    sleeves: str
    bottom: str
    bag: str
    hair: str
    helmet: bool = False


def _hex(h: str) -> np.ndarray:
    return srgb_to_linear(np.array([int(h[i:i + 2], 16) for i in (0, 2, 4)]) / 255.0)


def figure_materials(rng: np.random.Generator, helmet_color: np.ndarray | None = None) -> tuple[Material, ...]:
    """The figure's material table in slot order (skin, top, bottom, shoes, hair, bag, helmet); 10 draws."""
    u = rng.random(10)
    t = u[0] * (len(_SKIN) - 1)
    i = int(t)
    skin = (1 - (t - i)) * _hex(_SKIN[i]) + (t - i) * _hex(_SKIN[min(i + 1, len(_SKIN) - 1)])

    def pick(table: tuple[str, ...], x: float) -> np.ndarray:
        return _hex(table[int(x * len(table)) % len(table)])

    jitter = 0.9 + 0.2 * u[9]
    helmet = helmet_color if helmet_color is not None else pick(_TOPS, u[8])
    return (
        Material("skin", base_color=skin, roughness=0.5, specular=0.35),
        Material("fabric_top", base_color=np.clip(pick(_TOPS, u[1]) * jitter, 0, 1), roughness=0.8 + 0.15 * u[6]),
        Material("fabric_bottom", base_color=np.clip(pick(_BOTTOMS, u[2]) * jitter, 0, 1),
                 roughness=0.82 + 0.12 * u[7]),
        Material("shoes", base_color=pick(_SHOES, u[3]), roughness=0.6, specular=0.4),
        Material("hair", base_color=pick(_HAIR, u[4]), roughness=0.55, specular=0.45),
        Material("bag", base_color=pick(_BAGS, u[5]), roughness=0.75),
        Material("helmet", base_color=helmet, roughness=0.25, clearcoat=1.0),
    )


def draw_outfit(rng: np.random.Generator, child: bool, allow_skirt: bool = True, helmet: bool = False) -> Outfit:
    """A random outfit (5 draws)."""
    u = rng.random(5)
    sleeves = "short" if u[0] < 0.35 else "long"
    if u[1] < (0.16 if allow_skirt else 0.0):
        bottom = "skirt"
    elif u[1] < (0.32 if allow_skirt else 0.18):
        bottom = "shorts"
    else:
        bottom = "trousers"
    bag = "backpack" if u[2] < (0.22 if not child else 0.35) else ("shoulder" if u[2] < 0.36 and not child else "none")
    hair = "long" if u[3] < 0.35 else ("none" if u[3] > 0.93 and not child else "short")
    return Outfit(sleeves, bottom, "none" if helmet else bag, hair, helmet)


# ----------------------------------------------------------------------------- the mesh


def _torso(b: Body, J: dict[str, np.ndarray], material: int, bottom_material: int) -> MeshPart:
    """The trunk: a loft of ellipses along the pelvis -> neck axis (hips, waist, chest, shoulders)."""
    trunk = J["trunk"]
    pelvis = J["pelvis"]
    fwd = np.array([trunk[2], 0.0, -trunk[0]])  # forward, perpendicular to the trunk
    lat = np.array([0.0, 1.0, 0.0])
    H, g = b.height, b.girth
    span = b.shoulder_z - b.hip_z
    # (height above the hip joint as a fraction of span, half-width, half-depth, forward offset)
    s = np.array([-0.30, -0.26, -0.12, 0.10, 0.35, 0.60, 0.80, 0.93, 1.01, 1.06, 1.08])
    hw = np.array([0.055, 0.085, 0.100, 0.094, 0.083, 0.090, 0.098, 0.105, 0.085, 0.040, 0.0]) * H
    hd = np.array([0.040, 0.060, 0.068, 0.066, 0.060, 0.066, 0.070, 0.062, 0.050, 0.030, 0.0]) * H
    off = np.array([0.0, 0.0, -0.004, -0.002, 0.004, 0.010, 0.012, 0.004, -0.004, -0.006, -0.006]) * H
    hw[:-1] *= np.clip(b.shoulder_half / (0.1295 * H * 0.835 / 0.87 + 1e-9), 0.8, 1.3) ** 0.5 * g ** 0.7
    hd[:-1] *= g
    centres = pelvis[None] + (s * span)[:, None] * trunk + off[:, None] * fwd
    part = loft(ellipse_rings(centres, fwd, lat, hd, hw, 16), material)
    # below the waist the trunk wears the trousers / shorts / skirt
    waist = pelvis + 0.12 * span * trunk
    below = (part.vertices[part.faces].mean(axis=1) - waist) @ trunk < 0
    return with_material(part, np.where(below, bottom_material, material))


def _foot(b: Body, ankle: np.ndarray, toe: np.ndarray, sole_z: float, material: int) -> MeshPart:
    """A shoe: an ellipsoid from the heel to the toe, flat-soled at ``sole_z``."""
    fwd = toe / np.linalg.norm(toe)
    lat = np.array([-fwd[1], fwd[0], 0.0])
    Rm = np.stack([fwd, lat, np.array([0.0, 0.0, 1.0])], 1)
    centre = ankle + fwd * (0.22 * b.foot_len) + np.array([0.0, 0.0, -0.35 * b.ankle_h])
    radii = np.array([0.55 * b.foot_len, 0.5 * b.foot_w, 1.15 * b.ankle_h])
    return ellipsoid(centre, radii, material, rotation=Rm, n_around=12, n_rings=8, z_floor=sole_z)


def figure_parts(b: Body, J: dict[str, np.ndarray], outfit: Outfit, sole_z: float | None = None) -> list[MeshPart]:
    """The figure's closed segment meshes (material slots as in :func:`figure_materials`).

    ``sole_z``: height of the soles (default: the lowest ankle minus the ankle height).
    """
    if sole_z is None:
        sole_z = min(J["ankle_l"][2], J["ankle_r"][2]) - b.ankle_h
    parts = [_torso(b, J, TOP, BOTTOM)]
    neck_top = J["neck"] + 0.6 * b.neck_len * np.array([0.0, 0.0, 1.0]) + 0.3 * b.neck_len * J["trunk"]
    parts.append(capsule(J["neck"] - 0.03 * b.height * J["trunk"], neck_top, b.neck_r, b.neck_r * 0.95, SKIN,
                         n_around=10, n_cap=2))
    # Head: an egg-shaped ellipsoid above the neck, its chin at the neck's top.
    yaw, pitch = float(J["head_yaw"][0]), float(J["head_yaw"][1])
    Rh = rot_y(-pitch) @ np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0, 0, 1]])
    head_c = neck_top + np.array([0.10 * b.head_d, 0.0, 0.42 * b.head_h])
    head_r = np.array([0.5 * b.head_d, 0.5 * b.head_w, 0.53 * b.head_h])
    parts.append(ellipsoid(head_c, head_r, SKIN, rotation=Rh, n_around=16, n_rings=11))
    if outfit.helmet:
        parts.append(ellipsoid(head_c + Rh @ np.array([-0.02, 0.0, 0.12]) * b.head_h,
                               head_r * np.array([1.18, 1.22, 0.92]),
                               HELMET, rotation=Rh, n_around=16, n_rings=10))
    elif outfit.hair != "none":
        long_ = outfit.hair == "long"
        hc = head_c + Rh @ (np.array([-0.10, 0.0, 0.10 if not long_ else -0.02]) * b.head_h)
        hr = head_r * np.array([0.98, 1.06, 0.95 if not long_ else 1.12])
        parts.append(ellipsoid(hc, hr, HAIR, rotation=Rh, n_around=16, n_rings=10))
    sleeve_fore = TOP if outfit.sleeves == "long" else SKIN
    thigh_mat = BOTTOM if outfit.bottom != "skirt" else SKIN
    shin_mat = BOTTOM if outfit.bottom == "trousers" else SKIN
    for side in ("l", "r"):
        sh, el, wr = J[f"shoulder_{side}"], J[f"elbow_{side}"], J[f"wrist_{side}"]
        parts.append(capsule(sh, el, b.arm_r[0], b.arm_r[1], TOP, n_around=10, n_cap=2))
        parts.append(capsule(el, wr, b.forearm_r[0], b.forearm_r[1], sleeve_fore, n_around=10, n_cap=2))
        hdir = (wr - el) / np.linalg.norm(wr - el)
        lat = np.array([0.0, 1.0, 0.0]) - hdir * hdir[1]
        lat /= max(np.linalg.norm(lat), 1e-9)
        Rm = np.stack([np.cross(lat, hdir), lat, hdir], 1)
        parts.append(ellipsoid(wr + 0.45 * b.hand_len * hdir, np.array([0.11, 0.24, 0.5]) * b.hand_len, SKIN,
                               rotation=Rm, n_around=10, n_rings=7))
        hp, kn, an = J[f"hip_{side}"], J[f"knee_{side}"], J[f"ankle_{side}"]
        parts.append(capsule(hp, kn, b.thigh_r[0], b.thigh_r[1], thigh_mat, n_around=12, n_cap=2))
        parts.append(capsule(kn, an, b.shin_r[0], b.shin_r[1], shin_mat, n_around=10, n_cap=2))
        parts.append(_foot(b, an, J[f"toe_{side}"], sole_z, SHOES))
    if outfit.bottom == "skirt":
        top = J["pelvis"] + 0.12 * (b.shoulder_z - b.hip_z) * J["trunk"]
        knee_z = 0.5 * (J["knee_l"][2] + J["knee_r"][2]) + 0.04 * b.height
        length = top[2] - knee_z
        spread = max(abs(J["knee_l"][0] - J["knee_r"][0]), 0.0)
        rs = np.array([0.0, 0.088, 0.10, 0.12, 0.0]) * b.height * b.girth
        rs[3] = max(rs[3], 0.5 * spread + b.thigh_r[1] + 0.01)
        rs[4] = rs[3] * 0.9
        s = np.array([0.0, 0.0, 0.3, 1.0, 1.0]) * length
        rings = ellipse_rings(top[None] - s[:, None] * np.array([0.0, 0.0, 1.0]), np.array([1.0, 0, 0]),
                              np.array([0.0, 1.0, 0.0]), rs * np.array([0.8, 0.8, 0.85, 1.0, 1.0]), rs, 16)
        parts.append(loft(rings, BOTTOM))
    if outfit.bag == "backpack":
        trunk = J["trunk"]
        fwd = np.array([trunk[2], 0.0, -trunk[0]])
        half = np.array([0.045, 0.14, 0.2]) * b.height * 0.6  # half depth, width, height
        c = J["pelvis"] + 0.6 * (b.shoulder_z - b.hip_z) * trunk - (0.058 * b.height * b.girth + half[0]) * fwd
        Rm = np.stack([fwd, np.array([0.0, 1.0, 0.0]), trunk], 1)
        parts.append(ellipsoid(c, half * 1.3, BAG, rotation=Rm, n_around=16, n_rings=9, clamp=half))
    elif outfit.bag == "shoulder":
        c = J["pelvis"] + np.array([0.02, -(0.1 * b.girth + 0.03) * b.height, 0.07 * b.height])
        parts.append(ellipsoid(c, np.array([0.14, 0.04, 0.11]) * b.height * 0.6, BAG, n_around=10, n_rings=7))
        strap_top = J["shoulder_l"] + np.array([0.0, -0.02, 0.02])
        parts.append(capsule(strap_top, c + np.array([0.0, 0.0, 0.05 * b.height]), 0.008, 0.008, BAG, n_around=5,
                             n_cap=1))
    return parts


def rider_parts(rng: np.random.Generator | int, seat_xyz: np.ndarray, hands_xyz: np.ndarray, feet_xyz: np.ndarray,
                height: float, helmet: bool = False,
                helmet_color: np.ndarray | None = None) -> tuple[list[MeshPart], tuple[Material, ...]]:
    """A seated rider for a two-wheeler: its closed segment meshes and its material table.

    Args:
        rng: a generator or an int seed.
        seat_xyz: (3,) the top of the saddle, where the rider sits (object frame, metres).
        hands_xyz: (2, 3) left and right grip positions.
        feet_xyz: (2, 3) left and right pedal / foot-peg positions.
        height: the rider's standing height, metres.
        helmet: a motorcycle helmet instead of hair.
        helmet_color: optional linear RGB (3,) of the helmet.

    Returns:
        (parts, materials): the part's material slots index ``materials`` (offset them when merging).
    """
    g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng([int(rng) & 0xFFFFFFFF, 0x51DE])
    body = body_for(height, False, g)
    outfit = draw_outfit(g, child=False, allow_skirt=False, helmet=helmet)
    if outfit.bottom == "skirt":
        outfit = replace(outfit, bottom="trousers")
    mats = figure_materials(g, helmet_color)
    J = riding_joints(body, seat_xyz, hands_xyz, feet_xyz)
    parts = figure_parts(body, J, outfit, sole_z=float(np.min(np.asarray(feet_xyz)[:, 2])) - 0.015)
    return parts, mats


# ----------------------------------------------------------------------------- public entry point


def procedural_pedestrian(seed: int, wlh=None, variant: str | None = None, pose: str | None = None) -> Asset:
    """A pedestrian mesh, deterministic in (seed, wlh, variant, pose).

    Args:
        seed: random seed (proportions, pose, gait phase, outfit, colours).
        wlh: target box [w, l, h] metres or None (the category's mean).  The height is met within 1 %;
            w and l follow from the pose and are kept inside the category's min..max range.
        variant: ``adult`` / ``child`` or None (adult 90 %).
        pose: ``walking`` / ``standing`` or None (walking 60 %).

    Returns:
        An :class:`Asset` (category ``human.pedestrian.adult`` / ``.child``; attribute
        ``pedestrian.moving`` when walking, ``pedestrian.standing`` when standing), soles on z = 0.
        About 4-5 k triangles.

    Raises:
        ValueError: unknown variant or pose, or a wlh that is not 3 positive numbers.
    """
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x9ED5])
    u = rng.random(2)
    if variant is None:
        variant = "child" if u[0] < 0.1 else "adult"
    if variant not in _VARIANTS:
        raise ValueError(f"procedural_pedestrian: unknown variant {variant!r}; expected one of {', '.join(_VARIANTS)}")
    if pose is None:
        pose = "walking" if u[1] < 0.6 else "standing"
    if pose not in _POSES:
        raise ValueError(f"procedural_pedestrian: unknown pose {pose!r}; expected one of {', '.join(_POSES)}")
    category = _CATEGORY[variant]
    size = read_class_sizes()[category]
    if wlh is None:
        target_h = float(size.mean_wlh[2] * (0.94 + 0.12 * rng.random()))
    else:
        target = target_wlh(wlh, "procedural_pedestrian")
        rng.random()
        target_h = float(target[2])
    child = variant == "child"
    body = body_for(target_h, child, rng)
    outfit = draw_outfit(rng, child)
    materials = figure_materials(rng)
    pose_rng_state = rng.bit_generator.state
    lo, hi = size.min_wlh[:2] * 1.01, size.max_wlh[:2] * 0.99

    gain, spread = 1.0, 0.0
    for _ in range(12):
        rng.bit_generator.state = pose_rng_state  # the same pose draws; only the gain and spread change
        p = walking_pose(rng, gain) if pose == "walking" else standing_pose(rng, gain)
        p = replace(p, abduct=p.abduct + spread, stance=p.stance + 0.15 * spread * target_h)
        J = standing_joints(body, p)
        vertices, faces, fm, normals = _assemble(figure_parts(body, J, outfit))
        # Feet on z = 0, centred, height exactly the target.
        vmin, vmax = vertices.min(axis=0), vertices.max(axis=0)
        scale = target_h / (vmax[2] - vmin[2])
        vertices = (vertices - np.array([(vmin[0] + vmax[0]) / 2, (vmin[1] + vmax[1]) / 2, vmin[2]])) * scale
        ext = vertices.max(axis=0) - vertices.min(axis=0)
        w, l = ext[1], ext[0]
        # Newton-like steps: l grows with the feet's fore-aft spread (~ the gain), w with the arms' and
        # feet's sideways spread (~ arm length per radian of abduction, plus the stance)
        feet_dx = max(abs(J["ankle_l"][0] - J["ankle_r"][0]) * scale, 0.05 * target_h)
        arms = 2 * (body.upper_arm + body.forearm + body.hand_len) * scale + 0.3 * target_h
        ok = True
        if not lo[0] <= w <= hi[0]:
            goal = lo[0] * 1.02 if w < lo[0] else hi[0] * 0.98
            spread += (goal - w) / arms
            ok = False
        if not lo[1] <= l <= hi[1]:
            goal = lo[1] * 1.02 if l < lo[1] else hi[1] * 0.98
            gain *= float(np.clip(1.0 + (goal - l) / feet_dx, 0.5, 2.0))
            ok = False
        if ok:
            break
    asset = Asset(
        name=f"procedural-pedestrian-{variant}-{pose}-{seed}", vertices=vertices, faces=faces, face_material=fm,
        materials=materials, vertex_normals=normals, category=category, attribute=_ATTRIBUTE[pose],
    )
    return validate_asset(asset)


def _assemble(parts: list[MeshPart]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    V, F, M = merge_parts(parts)
    return V, F, M, np.concatenate([p.normals for p in parts])


__all__ = ["Body", "Outfit", "Pose", "body_for", "draw_outfit", "figure_materials", "figure_parts",
           "pedestrian_poses", "procedural_pedestrian", "procedural_pedestrian_variants", "rider_parts",
           "riding_joints", "standing_joints", "standing_pose", "walking_pose"]
