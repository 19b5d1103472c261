"""The UE4 (simplified Disney) BRDF of the paper, plus a clear-coat lobe, and GGX importance sampling.

All functions are vectorised over N shading samples.  Vectors are unit (N, 3) arrays in any one
frame; ``n`` is the shading normal, ``v`` points from the surface towards the viewer, ``l`` from
the surface towards the light.  BRDF values are in 1/sr (multiply by radiance and ``n.l``).

Model (``docs/method.md``): ``c_diff = (1 - m) c_base``, ``c_spec = (1 - m) 0.08 s + m c_base``,
GGX ``D`` with ``alpha = r^2``, Smith-Schlick ``G`` with ``k = (r + 1)^2 / 8``, Schlick ``F`` with the
spherical-Gaussian exponent ``2^((-5.55473 v.h - 6.98316) v.h)`` and, as in UE4's shader code,
``F90 = saturate(50 F0_green)`` so that specular = 0 really is a pure Lambertian.  The clear coat is a second GGX
lobe (roughness :data:`CLEARCOAT_ROUGHNESS`, F0 = 0.04) weighted by ``clearcoat``; the layer below
is attenuated by the light the coat reflects, ``1 - clearcoat F_c(v.h)``.

Metallic flakes (``flake`` k, car paint): a share k of the diffuse lobe is a rougher GGX lobe
(:data:`FLAKE_ROUGHNESS`, the spread of the flakes' orientations) of the diffuse colour,
``(1 - k) c_diff / pi + k c_diff [D_f G_f / (4 n.l n.v) + f_ms]``, without a Fresnel rim (the flakes are
seen through the coat, whose Fresnel already takes the grazing light).  ``f_ms = (1 - E(n.v)) (1 - E(n.l))
/ (pi (1 - E_avg))`` returns the light single scattering loses (Kulla & Conty 2017; ``E`` the lobe's
directional albedo, ``E_avg`` its cosine-weighted mean), so the flakes' albedo is exactly their share
of ``c_diff``: they move diffuse light towards the mirror direction (brighter near the highlight, darker
off it: the "flop" of metallic paint) and neither add nor lose energy.

Retro-reflection (cone and barrier bands, plates, signs) is a separate, narrow lobe around the
direction back to the light (:func:`retro_lobe`): ``f_r = c_r G(angle(v, l))`` with ``G`` a unit-integral
Gaussian of width :data:`RETRO_LOBE_RAD` and ``c_r = retro x min(RETRO_ALBEDO c_base, cap - c_diff)``
the fraction of the light it returns.  Its coefficient of retro-reflection ``R_A = f_r cos(l) cos(v)``
is ~210 cd/lx/m^2 coaxially for a white (0.8) base, the order of real sheeting; at a few degrees
from the light it is zero, so in daylight with the sun at the side the material is its base BRDF.
It is not part of :func:`eval_brdf` (a sampled lobe of 0.4 deg would only give fireflies): the
shader adds it for the sun's samples and in closed form for the environment.

Smooth dielectrics (windows, lamp lenses: roughness below :data:`PANE_ROUGHNESS` (0.1), faded out linearly by
0.15; non-metallic, no clear coat) reflect like a glass pane, not like Schlick's single face: the pane's exact
unpolarised Fresnel :func:`pane_reflectance` (two faces of n = :data:`PANE_IOR` with their multiple reflections,
per polarisation), mapped affinely so that it equals the material's F0 head-on and 1 at grazing
(:func:`pane_fresnel`).  The GGX lobe is scaled by ``sqrt(g(n.v) g(n.l))`` with ``g = pane_fresnel / E_spec``
(``E_spec`` the lobe's own directional albedo, :func:`specular_albedo`): reciprocal, and its mirror albedo
(:func:`mirror_albedo`, the shader's environment reflection) is the pane's reflectance exactly.  For clear glass
(F0 5.4 %) that is 5.4 % head-on, 14.7 % at 62 deg, 53 % at 80 deg (Schlick with the lobe's masking: 5.4, 7.2, 15):
a raked windscreen seen from a camera ahead mirrors the sky as real ones do.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..core import luminance

CLEARCOAT_ROUGHNESS = 0.05
CLEARCOAT_F0 = 0.04
MIN_ROUGHNESS = 0.03  # below this GGX is a delta lobe that a few samples cannot integrate
RETRO_ALBEDO = 0.08  # fraction of the light a full-strength retro-reflector returns into its narrow cone
RETRO_LOBE_RAD = np.radians(0.4)  # angular sigma of the returned cone (sheeting: R_A halves by ~0.5 deg)
RETRO_ENERGY_CAP = 0.96  # the diffuse colour plus the retro lobe's albedo stays below this (+ ~4 % specular)
FLAKE_ROUGHNESS = 0.45  # the flake lobe's GGX roughness (alpha 0.2: flake normals spread by ~10-15 deg)
PANE_IOR = 1.5  # refractive index of window and lamp-lens glass
PANE_ROUGHNESS = (0.1, 0.15)  # dielectrics smoother than this reflect with the pane's Fresnel, faded out by the second


@dataclass(frozen=True)
class BRDFParams:
    """Per-sample material parameters (N samples).

    Attributes:
        base_color: (N, 3) linear base colour in [0, 1].
        metallic: (N,) in [0, 1].
        roughness: (N,) perceptual roughness in [0, 1] (clamped to :data:`MIN_ROUGHNESS`).
        specular: (N,) UE4 specular, 0.5 = 4 % reflectance.
        clearcoat: (N,) clear-coat strength in [0, 1].
        retroreflective: (N,) retro-reflective strength in [0, 1], or None (none anywhere: no retro lobe).
        flake: (N,) metallic-flake share of the diffuse lobe in [0, 1], or None (none anywhere: no flake lobe).
    """

    base_color: np.ndarray
    metallic: np.ndarray
    roughness: np.ndarray
    specular: np.ndarray
    clearcoat: np.ndarray
    retroreflective: np.ndarray | None = None
    flake: np.ndarray | None = None

    @staticmethod
    def uniform(n: int, base_color=(0.8, 0.8, 0.8), metallic=0.0, roughness=0.5, specular=0.5, clearcoat=0.0,
                retroreflective=0.0, flake=0.0) -> "BRDFParams":
        """N identical samples (handy for tests)."""
        return BRDFParams(
            base_color=np.tile(np.asarray(base_color, dtype=np.float64), (n, 1)),
            metallic=np.full(n, float(metallic)),
            roughness=np.full(n, float(roughness)),
            specular=np.full(n, float(specular)),
            clearcoat=np.full(n, float(clearcoat)),
            retroreflective=np.full(n, float(retroreflective)) if retroreflective else None,
            flake=np.full(n, float(flake)) if flake else None,
        )

    @cached_property
    def lobe_probs(self) -> np.ndarray:
        """(N, 3) lobe sampling probabilities, see :func:`lobe_probabilities`."""
        return lobe_probabilities(self)

    def take(self, index: np.ndarray) -> "BRDFParams":
        """The parameters of the samples ``index`` (any numpy index); derived arrays already computed are taken too."""
        retro = None if self.retroreflective is None else self.retroreflective[index]
        flake = None if self.flake is None else self.flake[index]
        out = BRDFParams(*(getattr(self, f)[index] for f in ("base_color", "metallic", "roughness", "specular", "clearcoat")),
                         retroreflective=retro, flake=flake)
        for key in ("c_diff", "c_spec", "alpha", "lobe_probs", "c_retro", "pane_weight"):
            if self.__dict__.get(key) is not None:
                out.__dict__[key] = self.__dict__[key][index]
        return out

    def precompute(self, lobes: bool = True) -> "BRDFParams":
        """Compute the derived arrays now (so that :meth:`take` copies them instead of recomputing); without
        ``lobes`` not the lobe probabilities (only environment and BRDF samples need them)."""
        for key in ("c_diff", "c_spec", "alpha") + (("lobe_probs",) if lobes else ()):
            getattr(self, key)
        return self

    @cached_property
    def c_diff(self) -> np.ndarray:
        """(N, 3) diffuse colour."""
        return (1.0 - self.metallic)[:, None] * self.base_color

    @property
    def has_flake(self) -> bool:
        """Whether any sample has a flake lobe."""
        return self.flake is not None and bool(np.any(self.flake > 0))

    @cached_property
    def c_lambert(self) -> np.ndarray:
        """(N, 3) colour of the Lambertian lobe: the diffuse colour less the flakes' share (``c_diff`` without flakes)."""
        if self.flake is None:
            return self.c_diff
        return (1.0 - np.clip(self.flake, 0.0, 1.0))[:, None] * self.c_diff

    @cached_property
    def c_spec(self) -> np.ndarray:
        """(N, 3) specular colour at normal incidence (F0)."""
        m = self.metallic[:, None]
        return (1.0 - m) * 0.08 * self.specular[:, None] + m * self.base_color

    @cached_property
    def c_retro(self) -> np.ndarray | None:
        """(N, 3) fraction of the light the retro lobe returns (see the module docstring), or None."""
        if self.retroreflective is None:
            return None
        r = np.clip(self.retroreflective, 0.0, 1.0)[:, None]
        return r * np.clip(np.minimum(RETRO_ALBEDO * self.base_color, RETRO_ENERGY_CAP - self.c_diff), 0.0, None)

    @property
    def has_retro(self) -> bool:
        """Whether any sample has a retro-reflective lobe."""
        return self.retroreflective is not None and bool(np.any(self.retroreflective > 0))

    @cached_property
    def pane_weight(self) -> np.ndarray:
        """(N,) in [0, 1]: how far the specular lobe reflects with the pane's Fresnel (:func:`pane_fresnel`): 1 for
        smooth dielectrics (roughness < 0.1, no metal, no clear coat), fading out linearly by roughness 0.15."""
        lo, hi = PANE_ROUGHNESS
        smooth = np.clip((hi - self.roughness) / (hi - lo), 0.0, 1.0)
        return smooth * np.clip(1.0 - self.metallic, 0.0, 1.0) * np.clip(1.0 - self.clearcoat, 0.0, 1.0)

    @cached_property
    def alpha(self) -> np.ndarray:
        """(N,) GGX alpha = r^2."""
        return np.maximum(self.roughness, MIN_ROUGHNESS) ** 2


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def row_norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms (N,) of the rows of (N, 3) (much faster than ``np.linalg.norm(v, axis=1)``)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def ggx_d(n_dot_h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """GGX normal distribution D(h) (N,), normalised so that the integral of D (n.h) over h is 1."""
    a2 = alpha * alpha
    denom = n_dot_h * n_dot_h * (a2 - 1.0) + 1.0
    return a2 / (np.pi * denom * denom)


def smith_g(n_dot_l: np.ndarray, n_dot_v: np.ndarray, roughness: np.ndarray) -> np.ndarray:
    """Smith-Schlick geometry term with UE4's k = (r + 1)^2 / 8 (N,)."""
    k = (np.maximum(roughness, MIN_ROUGHNESS) + 1.0) ** 2 / 8.0
    return (n_dot_l / (n_dot_l * (1.0 - k) + k)) * (n_dot_v / (n_dot_v * (1.0 - k) + k))


def schlick_weight(v_dot_h: np.ndarray) -> np.ndarray:
    """UE4's spherical-Gaussian approximation of (1 - v.h)^5 (N,)."""
    return np.exp2((-5.55473 * v_dot_h - 6.98316) * v_dot_h)


def eval_brdf(n: np.ndarray, v: np.ndarray, l: np.ndarray, params: BRDFParams,
              mirror_spec_weight: np.ndarray | None = None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """BRDF value f(v, l) (N, 3), zero where ``n.l <= 0`` or ``n.v <= 0``.

    With ``mirror_spec_weight`` (N,), returns ``(f, f_mirror)``: also its near-mirror part, the clear coat
    plus that weight x the base's specular as the coat attenuates it (:func:`mirror_lobes`, computed once here).
    """
    n_l = _dot(n, l)
    n_v = _dot(n, v)
    ok = (n_l > 1e-6) & (n_v > 1e-6)
    n_l = np.clip(n_l, 1e-6, 1.0)
    n_v = np.clip(n_v, 1e-6, 1.0)
    h = v + l
    h /= np.maximum(row_norm(h)[:, None], 1e-12)
    n_h = np.clip(_dot(n, h), 0.0, 1.0)
    v_h = np.clip(_dot(v, h), 0.0, 1.0)
    fw = schlick_weight(v_h)[:, None]
    c_spec = params.c_spec
    f90 = np.clip(50.0 * c_spec[:, 1:2], 0.0, 1.0)  # UE4 (BRDF.ush): F0 < 2 % fades the Fresnel rim out
    F = c_spec + (f90 - c_spec) * fw
    spec = (ggx_d(n_h, params.alpha) * smith_g(n_l, n_v, params.roughness) / (4.0 * n_l * n_v))[:, None] * F
    pane = np.flatnonzero(params.pane_weight > 0)
    if len(pane):  # smooth glass: the pane's Fresnel, reciprocally (module docstring)
        r, c, w = params.roughness[pane], c_spec[pane], params.pane_weight[pane]
        spec[pane] *= np.sqrt(_pane_gain(n_v[pane], r, c, w) * _pane_gain(n_l[pane], r, c, w))
    if params.has_flake:
        f = params.c_lambert / np.pi + spec + flake_lobe(n_h, n_l, n_v, params)
    else:
        f = params.c_diff / np.pi + spec
    f_m = None if mirror_spec_weight is None else mirror_spec_weight[:, None] * spec
    cc = params.clearcoat
    if np.any(cc > 0):
        a_c = np.full_like(n_h, CLEARCOAT_ROUGHNESS**2)
        r_c = np.full_like(n_h, CLEARCOAT_ROUGHNESS)
        F_c = CLEARCOAT_F0 + (1.0 - CLEARCOAT_F0) * fw[:, 0]
        coat = ggx_d(n_h, a_c) * smith_g(n_l, n_v, r_c) / (4.0 * n_l * n_v) * F_c
        f = f * (1.0 - cc * F_c)[:, None] + (cc * coat)[:, None]
        if f_m is not None:
            f_m = f_m * (1.0 - cc * F_c)[:, None] + (cc * coat)[:, None]
    if f_m is None:
        return np.where(ok[:, None], f, 0.0)
    return np.where(ok[:, None], f, 0.0), np.where(ok[:, None], f_m, 0.0)


def mirror_lobes(n: np.ndarray, v: np.ndarray, l: np.ndarray, params: BRDFParams, spec_weight: np.ndarray) -> np.ndarray:
    """The near-mirror part of :func:`eval_brdf` (N, 3): the clear coat ``clearcoat x coat`` plus ``spec_weight``
    (N,) x the base's GGX specular as attenuated by the coat (zero where ``n.l`` or ``n.v <= 0``).

    Lobes this narrow reflect about one texel of any environment map: the shader uses them as a control
    variate whose expectation is the map at the mirror direction (:func:`mirror_albedo`)."""
    return eval_brdf(n, v, l, params, np.asarray(spec_weight, dtype=np.float64))[1]


def mirror_albedo(n_dot_v: np.ndarray, params: BRDFParams, spec_weight: np.ndarray,
                  spec_albedo: np.ndarray | None = None) -> np.ndarray:
    """``int mirror_lobes cos dl`` (N, 3), the lobes taken as mirrors (Fresnel and masking at ``n.l = n.v``): the
    coat's ``clearcoat F_c(n.v) G(n.v, n.v)`` plus ``spec_weight`` x the specular albedo x ``1 - clearcoat F_c(n.v)``
    (``spec_albedo`` (N, 3): :func:`specular_albedo` already computed, else computed here)."""
    n_v = np.clip(np.asarray(n_dot_v, dtype=np.float64), 1e-6, 1.0)
    F_c = CLEARCOAT_F0 + (1.0 - CLEARCOAT_F0) * schlick_weight(n_v)
    G_c = smith_g(n_v, n_v, np.full_like(n_v, CLEARCOAT_ROUGHNESS))
    out = (params.clearcoat * F_c * G_c)[:, None] * np.ones((1, 3))
    if np.any(spec_weight > 0):
        alb = specular_albedo(n_dot_v, params) if spec_albedo is None else spec_albedo
        w = params.pane_weight[:, None]
        if np.any(w > 0):  # the lobe's gain g(n.v) (n.l = n.v at the mirror) times its albedo: the pane's Fresnel
            alb = alb + w * (pane_fresnel(n_v, params.c_spec) - alb)
        out = out + (spec_weight * (1.0 - params.clearcoat * F_c))[:, None] * alb
    return out


def dielectric_fresnel(cos_i: np.ndarray, ior: float = PANE_IOR) -> tuple[np.ndarray, np.ndarray]:
    """Exact Fresnel reflectances (R_s, R_p), each (N,), of one face air -> dielectric of index ``ior`` at incidence
    cosines ``cos_i`` (N,) in [0, 1]."""
    c = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    c_t = np.sqrt(np.clip(1.0 - (1.0 - c * c) / (ior * ior), 0.0, 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        r_s = np.nan_to_num(((c - ior * c_t) / (c + ior * c_t)) ** 2, nan=1.0)
        r_p = np.nan_to_num(((c_t - ior * c) / (c_t + ior * c)) ** 2, nan=1.0)
    return r_s, r_p


def pane_reflectance(cos_i: np.ndarray, ior: float = PANE_IOR) -> np.ndarray:
    """Unpolarised reflectance (N,) of a clear, non-absorbing pane (two parallel faces of index ``ior``) with all
    its inner reflections: ``R + T^2 R / (1 - R^2) = 2 R / (1 + R)`` per polarisation (T = 1 - R), averaged.
    ~7.7 % head-on for n = 1.5, 16.8 % at 62 deg, 54 % at 80 deg, 1 at grazing."""
    r_s, r_p = dielectric_fresnel(cos_i, ior)
    return r_s / (1.0 + r_s) + r_p / (1.0 + r_p)


def pane_fresnel(n_dot_v: np.ndarray, f0: np.ndarray) -> np.ndarray:
    """The pane's reflectance (N, 3) at ``n_dot_v`` (N,) mapped affinely so that it is the material's F0 ``f0``
    (N, 3) head-on and 1 at grazing: ``F0 + (1 - F0) (P - P_0) / (1 - P_0)`` (P :func:`pane_reflectance`)."""
    t = ((pane_reflectance(n_dot_v) - _PANE_HEAD_ON) / (1.0 - _PANE_HEAD_ON))[:, None]
    return f0 + (1.0 - f0) * t


_PANE_HEAD_ON = float(pane_reflectance(np.ones(1))[0])  # the pane's reflectance at normal incidence (~7.7 %)


def mirror_fresnel(n_dot_v: np.ndarray, params: BRDFParams) -> np.ndarray:
    """The Fresnel reflectance (N, 3) of a mirror-like surface at ``n_dot_v`` (N,): Schlick's
    ``F0 + (1 - F0) (1 - n.v)^5``, blended into :func:`pane_fresnel` by ``params.pane_weight`` (smooth glass).
    What a ray that goes on through the glass loses: it is transmitted ``1 - F``."""
    n_v = np.clip(np.asarray(n_dot_v, dtype=np.float64), 0.0, 1.0)
    c_spec = params.c_spec
    F = c_spec + (1.0 - c_spec) * schlick_weight(n_v)[:, None]
    w = params.pane_weight[:, None]
    return F + w * (pane_fresnel(n_v, c_spec) - F) if np.any(w > 0) else F


def _pane_gain(n_dot: np.ndarray, roughness: np.ndarray, c_spec: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The pane lobe's gain (N, 3) at one direction (cosine ``n_dot`` (N,) to the normal): ``1 + w (g - 1)``,
    ``g = pane_fresnel / E_spec`` (``E_spec`` the GGX lobe's directional albedo there)."""
    e = _albedo_from_table(n_dot, roughness, c_spec)
    return 1.0 + weight[:, None] * (pane_fresnel(n_dot, c_spec) / np.maximum(e, 1e-6) - 1.0)


def flake_lobe(n_h: np.ndarray, n_l: np.ndarray, n_v: np.ndarray, params: BRDFParams) -> np.ndarray:
    """The flake lobe (N, 3), 1/sr: ``k c_diff [D G / (4 n.l n.v) + f_ms]`` at :data:`FLAKE_ROUGHNESS` (module docstring).

    ``n_h``, ``n_l``, ``n_v`` (N,) are the cosines (``n_l``, ``n_v`` clamped > 0 by the caller)."""
    r_f = np.full_like(n_h, FLAKE_ROUGHNESS)
    single = ggx_d(n_h, r_f * r_f) * smith_g(n_l, n_v, r_f) / (4.0 * n_l * n_v)
    multi = (1.0 - flake_energy(n_v)) * (1.0 - flake_energy(n_l)) / (np.pi * (1.0 - _flake_energy_avg()))
    return (np.clip(params.flake, 0.0, 1.0) * (single + multi))[:, None] * params.c_diff


def flake_energy(n_dot_v: np.ndarray) -> np.ndarray:
    """Directional albedo E (N,) of the white single-scattering flake lobe ``int D G / (4 n.l n.v) n.l dl``.

    :func:`specular_albedo` of a white metal at :data:`FLAKE_ROUGHNESS`, read from its table's column at that
    roughness (linear in n.v between the same nodes: the same values, ~10x cheaper than the 2-D lookup)."""
    global _FLAKE_E_COLUMN
    if _FLAKE_E_COLUMN is None:
        size = ALBEDO_TABLE_SIZE
        nodes = (np.arange(size) + 0.5) / size
        white = BRDFParams.uniform(size, base_color=(1.0, 1.0, 1.0), metallic=1.0, roughness=FLAKE_ROUGHNESS)
        _FLAKE_E_COLUMN = (nodes, specular_albedo(nodes, white)[:, 0])
    nodes, values = _FLAKE_E_COLUMN
    return np.interp(np.asarray(n_dot_v, dtype=np.float64), nodes, values)


_FLAKE_E_COLUMN: tuple[np.ndarray, np.ndarray] | None = None


_FLAKE_E_AVG: float | None = None


def _flake_energy_avg() -> float:
    """``E_avg = 2 int E(mu) mu dmu`` of :func:`flake_energy` (cached)."""
    global _FLAKE_E_AVG
    if _FLAKE_E_AVG is None:
        mu = (np.arange(256) + 0.5) / 256
        _FLAKE_E_AVG = float(2.0 * np.mean(flake_energy(mu) * mu))
    return _FLAKE_E_AVG


def flake_pick_share(n_dot_v: np.ndarray, params: BRDFParams) -> np.ndarray:
    """(N,) share of the diffuse lobe's BRDF samples that sample the flakes' GGX lobe: ``k E(n.v)`` (the rest,
    cosine-distributed, covers the Lambertian part and the flakes' multiple scattering)."""
    return np.clip(params.flake, 0.0, 1.0) * flake_energy(np.clip(n_dot_v, 0.0, 1.0))


def retro_lobe(n: np.ndarray, v: np.ndarray, l: np.ndarray, params: BRDFParams) -> np.ndarray:
    """Retro-reflective BRDF term (N, 3), 1/sr: ``c_retro G(angle(v, l))``, zero below the horizon or without retro.

    ``G = exp(-(1 - v.l) / sigma^2) / (2 pi sigma^2)`` (sigma = :data:`RETRO_LOBE_RAD`) integrates to 1 over
    the sphere; symmetric in ``v`` and ``l`` (reciprocal).
    """
    if params.c_retro is None:
        return np.zeros((len(n), 3))
    ok = (_dot(n, l) > 1e-6) & (_dot(n, v) > 1e-6)
    s2 = RETRO_LOBE_RAD**2
    g = np.exp(-np.clip(1.0 - _dot(v, l), 0.0, None) / s2) / (2.0 * np.pi * s2)
    return np.where(ok[:, None], params.c_retro * g[:, None], 0.0)


def retro_env_factor(n: np.ndarray, v: np.ndarray, params: BRDFParams) -> np.ndarray:
    """(N, 3) factor of the environment radiance L(v) (arriving from the viewer's direction) that the retro lobe
    returns to the viewer: ``int f_r L cos(l) dl ~ c_retro cos(v) L(v)`` (the lobe is narrower than any map texel)."""
    if params.c_retro is None:
        return np.zeros((len(n), 3))
    return params.c_retro * np.clip(_dot(n, v), 0.0, 1.0)[:, None]


# ----------------------------------------------------------------------------- sampling


def tangent_frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (t, b), each (N, 3), completing ``n`` to a right-handed frame (Duff et al. 2017)."""
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bt = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bt


def to_world(local: np.ndarray, n: np.ndarray, frame: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Directions (N, 3) given in the frame (t, b, n) of ``n`` -> the frame of ``n``.

    ``n`` may be (N, 3) or a single (3,) axis; ``frame`` = precomputed :func:`tangent_frame` of ``n``.
    """
    if n.ndim == 1:
        t, b = tangent_frame(n[None])
        return local @ np.stack([t[0], b[0], n])
    t, b = tangent_frame(n) if frame is None else frame
    return local[:, :1] * t + local[:, 1:2] * b + local[:, 2:3] * n


def sample_ggx_half(n: np.ndarray, alpha: np.ndarray, u1: np.ndarray, u2: np.ndarray,
                    frame: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Half vectors h (N, 3) distributed as D(h) (n.h) around ``n``, from uniforms u1, u2 (N,)."""
    a2 = alpha * alpha
    cos2 = (1.0 - u1) / (1.0 + (a2 - 1.0) * u1)
    cos_t = np.sqrt(np.clip(cos2, 0.0, 1.0))
    sin_t = np.sqrt(np.clip(1.0 - cos2, 0.0, 1.0))
    phi = 2.0 * np.pi * u2
    local = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)
    return to_world(local, n, frame)


def reflect(v: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Mirror ``v`` about ``h``: l = 2 (v.h) h - v, (N, 3)."""
    return 2.0 * _dot(v, h)[:, None] * h - v


def ggx_reflection_pdf(n: np.ndarray, v: np.ndarray, l: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Solid-angle pdf (N,) of ``l`` when ``h`` is drawn by :func:`sample_ggx_half` and ``l = reflect(v, h)``."""
    h = v + l
    h /= np.maximum(row_norm(h)[:, None], 1e-12)
    n_h = np.clip(_dot(n, h), 0.0, 1.0)
    v_h = np.maximum(_dot(v, h), 1e-6)
    return ggx_d(n_h, alpha) * n_h / (4.0 * v_h)


def lobe_probabilities(params: BRDFParams) -> np.ndarray:
    """Probabilities (N, 3) of sampling the (diffuse, specular, clear-coat) lobes for BRDF sampling.

    Proportional to each lobe's rough reflectance (luminance of c_diff, of c_spec plus a Fresnel
    allowance, clear-coat strength x 0.1), with a floor so that no lobe with weight is starved.
    """
    w_d = luminance(params.c_diff)
    w_s = luminance(params.c_spec) + 0.05
    w_c = 0.1 * params.clearcoat
    w = np.stack([w_d, w_s, w_c], axis=1)
    w = np.where(w > 0, np.maximum(w, 0.05 * w.sum(axis=1, keepdims=True)), 0.0)
    return w / w.sum(axis=1, keepdims=True)


def sample_brdf(n: np.ndarray, v: np.ndarray, params: BRDFParams, u: np.ndarray) -> np.ndarray:
    """Directions l (N, 3) drawn from the lobe mixture of :func:`lobe_probabilities`; u is (N, 3) uniform.

    With flakes, a share :func:`flake_pick_share` of the diffuse lobe's picks samples the flake lobe (GGX) instead.
    """
    probs = params.lobe_probs
    pick = u[:, 0]
    diffuse = pick < probs[:, 0]
    coat = pick >= probs[:, 0] + probs[:, 1]
    alpha = np.where(coat, CLEARCOAT_ROUGHNESS**2, params.alpha)
    if params.has_flake:
        flake = diffuse & (pick < probs[:, 0] * flake_pick_share(_dot(n, v), params))
        alpha = np.where(flake, FLAKE_ROUGHNESS**2, alpha)
        diffuse = diffuse & ~flake
    frame = tangent_frame(n)
    h = sample_ggx_half(n, alpha, u[:, 1], u[:, 2], frame)
    l = reflect(v, h)
    # Cosine-weighted hemisphere for the diffuse lobe (same uniforms).
    r = np.sqrt(u[:, 1])
    phi = 2.0 * np.pi * u[:, 2]
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.clip(1.0 - u[:, 1], 0.0, 1.0))], axis=1)
    l_d = to_world(local, n, frame)
    return np.where(diffuse[:, None], l_d, l)


def brdf_pdf(n: np.ndarray, v: np.ndarray, l: np.ndarray, params: BRDFParams) -> np.ndarray:
    """Solid-angle pdf (N,) of :func:`sample_brdf` producing ``l``."""
    probs = params.lobe_probs
    n_l = np.clip(_dot(n, l), 0.0, 1.0)
    if params.has_flake:
        q = flake_pick_share(_dot(n, v), params)
        p_diff = (1.0 - q) * n_l / np.pi + q * ggx_reflection_pdf(n, v, l, np.full(len(n), FLAKE_ROUGHNESS**2))
        pdf = probs[:, 0] * p_diff + probs[:, 1] * ggx_reflection_pdf(n, v, l, params.alpha)
    else:
        pdf = probs[:, 0] * n_l / np.pi + probs[:, 1] * ggx_reflection_pdf(n, v, l, params.alpha)
    if np.any(probs[:, 2] > 0):
        pdf = pdf + probs[:, 2] * ggx_reflection_pdf(n, v, l, np.full(len(n), CLEARCOAT_ROUGHNESS**2))
    return pdf


# ----------------------------------------------------------------------------- directional albedo

ALBEDO_TABLE_SIZE = 32


def _specular_albedo_table(size: int = ALBEDO_TABLE_SIZE, n_samples: int = 256) -> np.ndarray:
    """(size, size, 2) table over (n.v, roughness) cell centres of the specular lobe's directional albedo
    split by Fresnel: ``int f_spec cos dl = c_spec A + f90 B`` (UE4's "environment BRDF").

    Deterministic (Hammersley points, GGX importance sampling), so the table carries no noise.
    """
    k = np.arange(n_samples)
    u1 = (k + 0.5) / n_samples
    u2 = np.array([int(f"{i:032b}"[::-1], 2) for i in k], dtype=np.float64) / 2.0**32  # radical inverse
    centres = (np.arange(size) + 0.5) / size
    nv, rough, u1, u2 = _grid(centres, u1, u2)
    N = len(nv)
    v = np.stack([np.sqrt(1.0 - nv * nv), np.zeros(N), nv], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (N, 1))
    h = sample_ggx_half(n, np.maximum(rough, MIN_ROUGHNESS) ** 2, u1, u2)
    l = reflect(v, h)
    n_l = l[:, 2]
    v_h = np.clip(_dot(v, h), 0.0, 1.0)
    n_h = np.clip(h[:, 2], 1e-6, 1.0)
    w = np.where(n_l > 1e-6, smith_g(np.clip(n_l, 1e-6, 1.0), nv, rough) * v_h / (nv * n_h), 0.0)
    fw = schlick_weight(v_h)
    return np.stack([w * (1 - fw), w * fw], axis=1).reshape(size, size, n_samples, 2).mean(axis=2)


def _grid(centres: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, ...]:
    """(n.v, roughness, u1, u2) flattened over the (size, size, n_samples) grid."""
    size, n = len(centres), len(u1)
    nv = np.repeat(centres, size * n)
    rough = np.tile(np.repeat(centres, n), size)
    return nv, rough, np.tile(u1, size * size), np.tile(u2, size * size)


_ALBEDO_TABLE: np.ndarray | None = None


def specular_albedo(n_dot_v: np.ndarray, params: BRDFParams) -> np.ndarray:
    """Directional albedo (N, 3) of the specular (GGX) lobe, ``int f_spec(v, l) (n.l) dl``, from a cached table."""
    return _albedo_from_table(n_dot_v, params.roughness, params.c_spec)


def _albedo_from_table(n_dot_v: np.ndarray, roughness: np.ndarray, c_spec: np.ndarray) -> np.ndarray:
    """:func:`specular_albedo` (N, 3) from the lobe's roughness (N,) and F0 ``c_spec`` (N, 3)."""
    global _ALBEDO_TABLE
    if _ALBEDO_TABLE is None:
        _ALBEDO_TABLE = _specular_albedo_table()
    size = _ALBEDO_TABLE.shape[0]
    x = np.clip(np.asarray(n_dot_v, dtype=np.float64) * size - 0.5, 0.0, size - 1.0)
    y = np.clip(np.asarray(roughness, dtype=np.float64) * size - 0.5, 0.0, size - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), size - 2)
    y0 = np.minimum(np.floor(y).astype(np.int64), size - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    t = _ALBEDO_TABLE
    ab = (t[x0, y0] * (1 - fy) + t[x0, y0 + 1] * fy) * (1 - fx) + (t[x0 + 1, y0] * (1 - fy) + t[x0 + 1, y0 + 1] * fy) * fx
    f90 = np.clip(50.0 * c_spec[:, 1:2], 0.0, 1.0)
    return c_spec * ab[:, :1] + f90 * ab[:, 1:2]
