"""A Mitsuba 3 reference render of an insertion scene, to measure the renderer against (optional).

Mitsuba is not a runtime dependency: it is imported lazily, and only benchmarks and an optional test
use this module (``pip install mitsuba``; the ``scalar_rgb`` variant needs no LLVM).

The scene is what the contract's image form assumes, rendered with full global illumination:
a distant environment (sun included, as pixels of the map), an infinite-looking Lambertian ground
plane, and optionally the object.  Everything is expressed in the OpenCV camera frame of
:mod:`streetaug.augment.core` (x right, y down, z forward, metres)::

    Mitsuba camera / envmap local frame      OpenCV camera frame (= Mitsuba world here)
        y up, x left, z forward         --diag(-1,-1,1)-->     y down, x right, z forward

Convention checks (tested in ``tests/test_render_reference.py``):

* Camera: Mitsuba's perspective sensor looks along local +z with local +x = image left and +y = image
  up, so ``to_world = diag(-1, -1, 1)`` gives the OpenCV camera.  Mitsuba's film pixel (i, j) covers
  [i, i+1] x [j, j+1] (centre i + 0.5), OpenCV's covers [i - 0.5, i + 0.5]: the optical axis sits at
  film x = cx + 0.5.  Mitsuba measures its principal-point offset from the film centre towards film -x
  (found by the spot test), so ``principal_point_offset_x = (W/2 - cx - 0.5) / W`` (same for y with H).
  A box pixel filter matches the renderer's box-filtered (jittered) pixel samples.
* Environment: Mitsuba's ``envmap`` looks a local direction v up at u = atan2(v_x, -v_z) / 2 pi,
  v = acos(v_y) / pi; the camera-frame convention (lon = atan2(d_x, d_z), lat = asin(-d_y)) is the
  same map after v = diag(-1, -1, 1) d, so the camera-frame map is used as is with that ``to_world``.
* Materials (UE4 / glTF metallic-roughness -> Mitsuba): a pure Lambertian (metallic 0, specular 0, no
  clear coat: UE4's F90 rule makes it exactly Lambertian) -> ``diffuse``; anything else ->
  ``principled`` with the same base colour, metallic, roughness (alpha = r^2 in both), specular (0.5 =
  4 % in both) and clear coat.  Where they differ: Mitsuba's diffuse lobe is Burley's (retro-reflection)
  rather than Lambert's, its geometry term is the exact Smith GGX rather than Schlick with
  k = (r + 1)^2 / 8 (identical at r = 1), its dielectric Fresnel is exact rather than Schlick, and its
  clear coat is GTR1.  Metals are nearly exact (Schlick F from the base colour in both).  Metallic flakes
  (``flake`` k > 0) -> ``blendbsdf`` of weight k between that principled BSDF and a principled metal of the
  diffuse colour at :data:`~streetaug.augment.render.brdf.FLAKE_ROUGHNESS` with the same clear coat: the
  diffuse share and the flake lobe are the renderer's, but the blend also scales the dielectric specular
  by 1 - k (kept whole in the renderer) and Mitsuba's metal has a Fresnel rim towards white (the renderer's
  flakes have none); there is no flake lobe in Mitsuba's principled BSDF to map to exactly.  Opacity < 1
  (glass) -> ``mask`` (straight transmission of 1 - opacity), which only approximates the renderer's
  thin glass.  Textures are not mapped (the constant factors are used).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..assets.asset import Asset, Material
from ..core import camera_envmap_directions, check_shape, equirect_solid_angles
from ..render.brdf import FLAKE_ROUGHNESS, MIN_ROUGHNESS

FLIP = np.diag([-1.0, -1.0, 1.0, 1.0])  # Mitsuba local (x left, y up) <-> OpenCV (x right, y down)
GROUND_HALF_SIZE_M = 20_000.0


def mitsuba_available() -> tuple[bool, str]:
    """(True, "") if Mitsuba 3 with the ``scalar_rgb`` variant can be used, else (False, why not)."""
    try:
        import mitsuba as mi
    except ImportError as e:  # pragma: no cover - depends on the environment
        return False, f"mitsuba is not installed ({e}); pip install mitsuba"
    if "scalar_rgb" not in mi.variants():  # pragma: no cover
        return False, f"mitsuba {mi.__version__} has no scalar_rgb variant"
    return True, ""


def _mi():
    import mitsuba as mi

    if mi.variant() != "scalar_rgb":
        mi.set_variant("scalar_rgb")
    return mi


@dataclass(frozen=True)
class ReferenceScene:
    """One insertion scene in the camera frame.

    Attributes:
        K: (3, 3) intrinsics (pixel centres at integers).
        width, height: image size in pixels.
        envmap_cam: (h, w, 3) float32 linear radiance, camera-frame equirect convention, sun included.
        ground_normal_cam: (3,) unit up normal of the ground plane n . p + d = 0.
        ground_offset_m: d of that plane (1.5 for a level camera 1.5 m above the ground).
        ground_albedo: (3,) Lambertian albedo of the ground.
        asset: the object, or None for the empty scene.
        T_cam_from_object: (4, 4) object pose (ignored without an asset).
    """

    K: np.ndarray
    width: int
    height: int
    envmap_cam: np.ndarray
    ground_normal_cam: np.ndarray
    ground_offset_m: float
    ground_albedo: np.ndarray
    asset: Asset | None = None
    T_cam_from_object: np.ndarray | None = None

    def without_object(self) -> "ReferenceScene":
        return ReferenceScene(self.K, self.width, self.height, self.envmap_cam, self.ground_normal_cam,
                              self.ground_offset_m, self.ground_albedo)


def ground_radiance(envmap_cam: np.ndarray, up_cam: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """Radiance (3,) of an unshadowed Lambertian ground: albedo / pi x irradiance from the sky above it."""
    H, W = envmap_cam.shape[:2]
    cos = camera_envmap_directions(H, W) @ np.asarray(up_cam, dtype=np.float64)
    E = np.einsum("hw,hwc->c", np.clip(cos, 0.0, None) * equirect_solid_angles(H, W), envmap_cam.astype(np.float64))
    return np.asarray(albedo, dtype=np.float64) * E / np.pi


def with_ground_below_horizon(envmap_cam: np.ndarray, up_cam: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """The map with every direction below the horizon replaced by the unshadowed ground's radiance.

    This is the local environment a perfect light estimate gives for a point on the ground: sky above,
    the (Lambertian, unshadowed) ground below.
    """
    env = np.array(envmap_cam, dtype=np.float32, copy=True)
    H, W = env.shape[:2]
    below = camera_envmap_directions(H, W) @ np.asarray(up_cam, dtype=np.float64) < 0
    env[below] = ground_radiance(envmap_cam, up_cam, albedo).astype(np.float32)
    return env


def mitsuba_bsdf(material: Material) -> dict:
    """Mitsuba BSDF dict for a UE4 material (see the module docstring for what is exact)."""
    base = np.clip(np.asarray(material.base_color, dtype=np.float64)[:3], 0.0, 1.0)
    rgb = {"type": "rgb", "value": base.tolist()}
    if material.metallic <= 0 and material.specular <= 0 and material.clearcoat <= 0:
        bsdf = {"type": "diffuse", "reflectance": rgb}
    else:
        bsdf = {"type": "principled", "base_color": rgb, "metallic": float(material.metallic),
                "roughness": float(max(material.roughness, MIN_ROUGHNESS)),
                "specular": float(material.specular), "clearcoat": float(material.clearcoat),
                "clearcoat_gloss": 0.95}
    flake = float(np.clip(getattr(material, "flake", 0.0), 0.0, 1.0))
    if flake > 0 and bsdf["type"] == "principled":
        c_diff = (1.0 - float(material.metallic)) * base
        flakes = {"type": "principled", "base_color": {"type": "rgb", "value": c_diff.tolist()}, "metallic": 1.0,
                  "roughness": FLAKE_ROUGHNESS, "clearcoat": float(material.clearcoat), "clearcoat_gloss": 0.95}
        bsdf = {"type": "blendbsdf", "weight": flake, "bsdf_0": bsdf, "bsdf_1": flakes}
    if material.opacity < 1.0:
        bsdf = {"type": "mask", "opacity": float(material.opacity), "material": bsdf}
    return bsdf


def _mesh(mi, name: str, V: np.ndarray, F: np.ndarray, N: np.ndarray, bsdf: dict, emission: np.ndarray):
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    if np.any(np.asarray(emission) > 0):
        props["emitter"] = mi.load_dict({"type": "area", "radiance": {"type": "rgb", "value": np.asarray(emission)[:3].tolist()}})
    mesh = mi.Mesh(name, len(V), len(F), props=props, has_vertex_normals=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = np.ascontiguousarray(V, dtype=np.float32).ravel()
    params["faces"] = np.ascontiguousarray(F, dtype=np.uint32).ravel()
    params["vertex_normals"] = np.ascontiguousarray(N, dtype=np.float32).ravel()
    params.update()
    return mesh


def _object_meshes(mi, asset: Asset, T_cam_from_object: np.ndarray) -> dict:
    """One Mitsuba mesh per material, vertices and normals in the camera frame."""
    R, t = T_cam_from_object[:3, :3], T_cam_from_object[:3, 3]
    out = {}
    for m_index, mat in enumerate(asset.materials):
        faces = asset.faces[asset.face_material == m_index]
        if len(faces) == 0:
            continue
        used, inverse = np.unique(faces, return_inverse=True)
        V = asset.vertices[used] @ R.T + t
        N = asset.vertex_normals[used] @ R.T
        out[f"object_{m_index}"] = _mesh(mi, f"object_{m_index}", V, inverse.reshape(-1, 3), N, mitsuba_bsdf(mat),
                                         mat.emission)
    return out


def build_scene(scene: ReferenceScene, spp: int = 64, max_depth: int = 8, crop: tuple[int, int, int, int] | None = None,
                sampler: str = "multijitter"):
    """The Mitsuba scene object (loaded once; render it many times with :func:`render`).

    Args:
        scene: what to render.
        spp: default samples per pixel (``render`` can override).
        max_depth: path length limit of the path tracer (Russian roulette from depth 5).
        crop: optional (x0, y0, x1, y1) end-exclusive pixel window to render instead of the full frame.
    """
    mi = _mi()
    K = np.asarray(scene.K, dtype=np.float64)
    check_shape(K, (3, 3), "K")
    W, H = int(scene.width), int(scene.height)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if abs(fx - fy) > 1e-6 * fx or abs(K[0, 1]) > 1e-9:
        raise ValueError("reference camera: needs square pixels (fx == fy) and no skew")
    film = {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}, "pixel_format": "rgb",
            "component_format": "float32"}
    if crop is not None:
        x0, y0, x1, y1 = (int(v) for v in crop)
        film.update(crop_offset_x=x0, crop_offset_y=y0, crop_width=x1 - x0, crop_height=y1 - y0)
    flip = mi.ScalarTransform4f(FLIP.tolist())
    env = np.ascontiguousarray(scene.envmap_cam, dtype=np.float32)
    check_shape(env, ("h", "w", 3), "envmap_cam")
    n = np.asarray(scene.ground_normal_cam, dtype=np.float64)
    n = n / np.linalg.norm(n)
    # Ground: Mitsuba's rectangle is [-1, 1]^2 in z = 0 with normal +z; map +z to n, centre under the camera.
    a = np.cross(n, [1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.cross(n, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    G = np.eye(4)
    G[:3, :3] = np.stack([a, b, n], axis=1) * np.array([GROUND_HALF_SIZE_M, GROUND_HALF_SIZE_M, 1.0])
    G[:3, 3] = -float(scene.ground_offset_m) * n
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(max_depth), "rr_depth": 5, "hide_emitters": False},
        "sensor": {
            "type": "perspective", "fov_axis": "x", "fov": float(np.degrees(2 * np.arctan(W / (2 * fx)))),
            "principal_point_offset_x": float((W / 2 - cx - 0.5) / W),
            "principal_point_offset_y": float((H / 2 - cy - 0.5) / H),
            "near_clip": 0.01, "far_clip": 1e6, "to_world": flip, "film": film,
            "sampler": {"type": sampler, "sample_count": int(spp)},
        },
        "env": {"type": "envmap", "bitmap": mi.Bitmap(env), "to_world": flip},
        "ground": {"type": "rectangle", "to_world": mi.ScalarTransform4f(G.tolist()),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": np.asarray(scene.ground_albedo, dtype=np.float64).tolist()}}},
    }
    if scene.asset is not None:
        d.update(_object_meshes(mi, scene.asset, np.asarray(scene.T_cam_from_object, dtype=np.float64)))
    return mi.load_dict(d)


def render(mi_scene, spp: int, seed: int = 0, threads: int | None = None) -> tuple[np.ndarray, float]:
    """Render a scene from :func:`build_scene`: ((h, w, 3) float32 linear radiance, seconds of rendering).

    The time covers ``mi.render`` only (scene loading excluded).  ``threads`` sets Mitsuba's thread pool
    (1 = the renderer's single core).
    """
    mi = _mi()
    import drjit as dr

    if threads is not None:
        dr.set_thread_count(int(threads))
    t0 = time.perf_counter()
    img = mi.render(mi_scene, spp=int(spp), seed=int(seed))
    arr = np.array(img, dtype=np.float32)
    return arr, time.perf_counter() - t0
