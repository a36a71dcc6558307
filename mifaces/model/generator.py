"""The face generator behind the built-in model (:mod:`mifaces.model.builtin`):
a cylindrical template head with anthropometric features, individuals drawn
from Farkas' measurements and warped onto it in dense correspondence, their
albedos, expressions, iBUG landmarks and the region map (details and sources
in ``docs/model.md``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from .regions import REGIONS

# ---- the template grid -------------------------------------------------------------------
H_MIN, H_MAX, H_STEP = -135.0, 100.0, 1.0          # mm; eye line (endocanthion) at h = 0
PHI_MAX, PHI_STEP = np.radians(100.0), np.radians(0.8)
R0 = 85.0  # mm: arc length s = R0 * phi measures lateral distances on the template
REGION_MAP_SHAPE = (1024, 1024)
POPULATION = 200

# ---- anthropometry: (female mean, male mean, standard deviation), mm ---------------------
# Farkas 1994 (Anthropometry of the Head and Face, 2nd ed., tables for North
# American Caucasians aged 19-25), rounded to 0.5 mm; see docs/model.md.
FARKAS = {
    "tr_n": (58.5, 61.5, 6.0),     # forehead height, trichion - nasion
    "n_sn": (50.5, 54.5, 3.2),     # nose height, nasion - subnasale
    "sn_sto": (20.0, 22.5, 2.0),   # upper lip height, subnasale - stomion
    "sto_gn": (42.0, 45.0, 3.5),   # lower face: stomion - gnathion (n-gn 112 / 121)
    "ls_sto": (8.5, 9.0, 1.4),     # upper vermilion height
    "sto_li": (9.5, 10.5, 1.7),    # lower vermilion height
    "zy_zy": (130.0, 137.0, 5.0),  # face width, bizygomatic
    "go_go": (91.0, 97.0, 6.0),    # mandible width, bigonial
    "ft_ft": (108.0, 112.0, 5.0),  # minimum frontal width
    "en_en": (32.0, 33.5, 2.5),    # intercanthal width
    "ex_ex": (88.0, 91.0, 3.2),    # biocular width
    "al_al": (31.5, 35.0, 2.0),    # nose width
    "sn_prn": (19.0, 20.0, 2.0),   # nasal tip protrusion
    "ch_ch": (50.0, 54.5, 3.3),    # mouth width
}
# Feature depths without a Farkas table: (female, male, sd), mm.
DEPTHS = {
    "brow_ridge": (2.0, 4.0, 1.0),
    "eye_depth": (7.0, 7.5, 1.2),
    "nasal_root": (3.0, 4.0, 1.2),
    "cheekbone": (3.0, 3.0, 1.2),
    "cheek_fullness": (2.0, 1.0, 1.5),
    "chin": (3.0, 4.0, 1.5),
    "lip_fullness": (2.6, 2.2, 0.6),
    "forehead_slope": (0.0, 4.0, 3.0),
    "face_depth": (0.0, 3.0, 3.0),
}


def _mean_params() -> dict[str, float]:
    p = {k: 0.5 * (f + m) for k, (f, m, _) in FARKAS.items()}
    p.update({k: 0.5 * (f + m) for k, (f, m, _) in DEPTHS.items()})
    return p


TEMPLATE = _mean_params()


@dataclass(frozen=True)
class Grid:
    """The template grid: heights h0 (rows, top first) and azimuths phi0 (columns)."""

    h: np.ndarray
    phi: np.ndarray

    @property
    def shape(self):
        return len(self.h), len(self.phi)


def template_grid() -> Grid:
    rows = int(round((H_MAX - H_MIN) / H_STEP)) + 1
    cols = int(round(2 * PHI_MAX / PHI_STEP)) + 1
    return Grid(np.linspace(H_MAX, H_MIN, rows), np.linspace(-PHI_MAX, PHI_MAX, cols))


def grid_triangles(rows: int, cols: int) -> np.ndarray:
    """Two triangles per grid cell, counter-clockwise seen from outside (+r)."""
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (i * cols + j).ravel()
    b, c, d = a + 1, a + cols, a + cols + 1  # right, below, below-right
    # Rows go down in h, columns go towards +x; seen from outside (+r), (a, c, b)
    # is counter-clockwise.
    return np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)]).astype(np.int32)


# ---- small smooth functions -------------------------------------------------------------
def _gauss(x):
    return np.exp(-0.5 * x * x)


def _smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _window(x, inner, outer):
    """1 for |x| <= inner, smoothly 0 beyond outer."""
    return 1.0 - _smoothstep(inner, outer, np.abs(x))


# ---- template landmarks (h0 in mm, s0 = R0 * phi0 in mm) ---------------------------------
def template_heights(p: dict) -> dict[str, float]:
    """Heights of the landmarks for measurements ``p`` (eye line fixed at 0)."""
    n = 9.0
    sn = n - p["n_sn"]
    sto = sn - p["sn_sto"]
    return {
        "gn": sto - p["sto_gn"], "li": sto - p["sto_li"], "sto": sto, "ls": sto + p["ls_sto"],
        "sn": sn, "prn": sn + 8.0, "en": 0.0, "n": n, "brow": n + 14.0, "tr": n + p["tr_n"],
        "top": n + p["tr_n"] + 31.0,
    }


_T = template_heights(TEMPLATE)
_KNOTS = ("gn", "li", "sto", "ls", "sn", "prn", "en", "n", "brow", "tr")


class _Features:
    """Feature outlines of the template, in template coordinates (h0, s0)."""

    # Eye corners: arc lengths s whose chord x = r sin(s / R0) is the measured
    # half width, at the radii the corners end up at (82 mm inner, 78 mm outer).
    eye_inner = R0 * np.arcsin(TEMPLATE["en_en"] / 2.0 / 82.0)
    eye_outer = R0 * np.arcsin(TEMPLATE["ex_ex"] / 2.0 / 78.0)
    eye_c = 0.5 * (eye_inner + eye_outer)  # eye centre |s|
    eye_half = 0.5 * (eye_outer - eye_inner)  # fissure half length
    eye_h = 0.8  # fissure centre height
    lid_up, lid_lo = 5.5, 4.5  # palpebral fissure, above/below its centre (ps-pi ~ 10 mm)
    mouth_half = TEMPLATE["ch_ch"] / 2.0
    nose_half = TEMPLATE["al_al"] / 2.0

    @classmethod
    def eye_t(cls, s):
        return (np.abs(s) - cls.eye_c) / cls.eye_half

    @classmethod
    def lids(cls, s):
        """Upper and lower eyelid margins (heights) over the fissure; NaN-free outside."""
        t = np.clip(cls.eye_t(s), -1.0, 1.0)
        # Almond: the upper lid peaks slightly medially, the lower lid laterally.
        up = cls.eye_h + cls.lid_up * (1.0 - t * t) ** 0.7 * (1.0 - 0.12 * t)
        lo = cls.eye_h - cls.lid_lo * (1.0 - t * t) ** 0.9 * (1.0 + 0.1 * t)
        return up, lo

    @classmethod
    def eye_mask(cls, h, s, soften=0.6):
        """Smooth indicator of the palpebral fissure (the visible eyeball)."""
        up, lo = cls.lids(s)
        inside_t = _window(cls.eye_t(s), 0.97, 1.0)
        return (_smoothstep(lo - soften, lo + soften, h) * (1.0 - _smoothstep(up - soften, up + soften, h))
                * inside_t)

    @classmethod
    def brow(cls, s):
        """Lower and upper edge of the eyebrow over |s|; the band's weight."""
        t = (np.abs(s) - (cls.eye_c + 1.0)) / 22.0
        centre = _T["n"] + 5.0 + 4.0 * (1.0 - t * t) - 1.5 * t
        thick = 3.3 - 1.3 * t  # half thickness, thicker medially
        weight = _window(t, 0.85, 1.05) * _smoothstep(-1.1, -0.9, t)
        return centre - thick, centre + thick, weight

    @classmethod
    def lips(cls, s):
        """Upper lip vermilion border (labrale line) and lower lip border, heights over |s|."""
        t = np.clip(np.abs(s) / cls.mouth_half, 0.0, 1.0)
        sto = _T["sto"] + 1.2 * (1.0 - t * t)  # mouth line curves slightly
        bow = 1.2 * _gauss((np.abs(s) - 5.0) / 2.5) - 0.6 * _gauss(s / 2.0)  # Cupid's bow
        up = sto + (_T["ls"] - _T["sto"]) * (1.0 - t ** 2.2) ** 0.6 + bow * (1.0 - t)
        lo = sto - (_T["sto"] - _T["li"]) * (1.0 - t ** 2.0) ** 0.7
        return up, sto, lo

    @classmethod
    def nostrils(cls, h, s):
        """Smooth indicator of the nostril openings on the underside of the nose."""
        d = ((np.abs(s) - 6.0) / 3.0) ** 2 + ((h - (_T["sn"] + 3.0)) / 1.7) ** 2
        return 1.0 - _smoothstep(0.7, 1.0, d)

    @classmethod
    def hairline(cls, s):
        """Height of the hairline over |s| (recedes at the temples, comes down at the sideburns)."""
        a = np.abs(s)
        return (_T["tr"] + 6.0 * (a / 60.0) ** 2 - 10.0 * _smoothstep(55.0, 80.0, a)
                - 60.0 * _smoothstep(95.0, 115.0, a))

    @classmethod
    def beard(cls, h, s):
        """Smooth indicator of the beard area (upper lip, chin, jaw, under the chin)."""
        a = np.abs(s)
        # Upper border: below the nose, down over the cheeks, up again to the sideburns.
        upper = np.interp(a, [0.0, cls.nose_half + 2.0, 34.0, 52.0, 78.0, 100.0],
                          [_T["sn"] - 1.0, _T["sn"] - 1.0, _T["sn"] - 10.0, -62.0, -38.0, -5.0])
        side = 1.0 - _smoothstep(100.0, 112.0, a)
        return _smoothstep(upper + 1.5, upper - 1.5, h) * side


F = _Features


# ---- one face ----------------------------------------------------------------------------
def _warp(p: dict, h0: np.ndarray, s0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map template coordinates to the individual's (h, s): landmarks to their new places."""
    T = template_heights(p)
    src = np.array([H_MIN, *[_T[k] for k in _KNOTS], H_MAX])
    dst = np.array([T["gn"] - (_T["gn"] - H_MIN), *[T[k] for k in _KNOTS], T["top"] + (H_MAX - _T["top"])])
    h = PchipInterpolator(src, dst)(h0)
    # Lateral scale: face width by height band, then local widths of eyes, nose, mouth.
    width = PchipInterpolator(
        [H_MIN, _T["gn"], _T["sto"] - 10, -20.0, _T["brow"], _T["tr"], H_MAX],
        [p["go_go"] / TEMPLATE["go_go"], p["go_go"] / TEMPLATE["go_go"],
         0.5 * (p["go_go"] / TEMPLATE["go_go"] + p["zy_zy"] / TEMPLATE["zy_zy"]),
         p["zy_zy"] / TEMPLATE["zy_zy"], p["ft_ft"] / TEMPLATE["ft_ft"],
         p["ft_ft"] / TEMPLATE["ft_ft"], p["ft_ft"] / TEMPLATE["ft_ft"]])(h0)
    a = np.abs(s0)
    local = 1.0
    # Eyes: biocular width sets the outer corners, intercanthal width the inner ones.
    eye_band = _window(h0 - F.eye_h, 14.0, 24.0)
    inner = p["en_en"] / TEMPLATE["en_en"]
    outer = p["ex_ex"] / TEMPLATE["ex_ex"]
    eye_scale = np.interp(a, [0.0, F.eye_inner, F.eye_outer, 75.0], [inner, inner, outer, 1.0])
    local = local + (eye_scale - 1.0) * eye_band
    nose_band = _window(h0 - (_T["sn"] + 6.0), 10.0, 18.0) * _window(a, F.nose_half + 4.0, F.nose_half + 16.0)
    local = local + (p["al_al"] / TEMPLATE["al_al"] - 1.0) * nose_band
    mouth_band = _window(h0 - _T["sto"], 12.0, 20.0) * _window(a, F.mouth_half + 4.0, F.mouth_half + 18.0)
    local = local + (p["ch_ch"] / TEMPLATE["ch_ch"] - 1.0) * mouth_band
    # Blend local scales into the face width away from the midline features.
    s = s0 * width * local
    return h, s


def _radius(p: dict, h0: np.ndarray, s0: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Radius of the individual's surface at template point (h0, s0), drawn at azimuth phi."""
    a = np.abs(s0)
    # Base head: superellipse cross-section, half-width A(h), midline depth B(h).
    dh = p["face_depth"]
    slope = p["forehead_slope"]
    hk = [H_MIN, _T["gn"] - 16, _T["gn"] - 6, _T["gn"], _T["gn"] + 10, _T["li"] - 6, _T["sto"], _T["sn"],
          -20.0, 0.0, _T["n"], _T["brow"], 40.0, _T["tr"], H_MAX]
    B = PchipInterpolator(hk, [56, 60, 74, 84, 87, 84, 88, 88.5, 86.5, 84, 85.5, 90, 91.5 - 0.3 * slope,
                               88 - slope, 64 - slope])(h0) + dh
    A = PchipInterpolator([H_MIN, _T["gn"] - 10, _T["gn"], _T["sto"], -20.0, 0.0, 40.0, H_MAX],
                          [50, 50, 50, 60, 68, 71, 74, 64])(h0)
    pw = PchipInterpolator([H_MIN, _T["gn"], _T["sto"], -20.0, 40.0, H_MAX], [2.2, 2.0, 2.3, 2.6, 2.6, 2.3])(h0)
    r = (np.abs(np.sin(phi) / A) ** pw + np.abs(np.cos(phi) / B) ** pw) ** (-1.0 / pw)
    face = _window(s0, 60.0, 100.0)  # the features fade out towards the sides of the head

    # Brow ridge (supraorbital) and glabella.
    r += p["brow_ridge"] * _gauss((h0 - (_T["n"] + 10.0)) / 6.0) * _window(a - 5.0, 35.0, 55.0)
    # Eye sockets: the orbit is deepest under the brow, medially.
    socket = _gauss((a - (F.eye_c - 1.0)) / 13.0) * _gauss((h0 - (F.eye_h + 1.5)) / 10.0)
    r -= p["eye_depth"] * socket
    # Eyelids: slight bulge over the eyeball, a crease above the upper lid.
    up, lo = F.lids(s0)
    eye_t = F.eye_t(s0)
    lid_area = _gauss(eye_t / 1.05) * _gauss((h0 - F.eye_h) / 7.0)
    r += 3.0 * lid_area
    r -= 1.0 * _gauss((h0 - (up + 3.5)) / 1.2) * _window(eye_t, 0.8, 1.1)
    # Eyeball: a sphere (radius 12 mm) seen through the fissure, the lid margins 1.2 mm above it.
    ball = np.sqrt(np.maximum(144.0 - (h0 - F.eye_h) ** 2 - (a - F.eye_c) ** 2, 0.0)) - 12.0
    cornea = 1.0 * _gauss(np.hypot(h0 - F.eye_h, a - F.eye_c) / 3.5)
    eye_surface = (r.copy() - 1.2) + 0.5 * (ball + cornea)
    m = F.eye_mask(h0, s0)
    r = r * (1.0 - m) + eye_surface * m

    # Nose: dorsum from the nasal root to the tip, rounded underside, alae, nostrils.
    tip_h = _T["prn"]
    t = np.clip((_T["n"] - h0) / (_T["n"] - tip_h), 0.0, 1.0)
    protrusion = p["sn_prn"] + 6.5  # the alae and lip below add depth; this gives sn-prn on the mean
    above = p["nasal_root"] + (protrusion - p["nasal_root"]) * t ** 1.15
    under = np.sqrt(np.clip(1.0 - ((tip_h - h0) / (tip_h - _T["sn"] + 0.8)) ** 2, 0.0, 1.0))
    profile = np.where(h0 >= tip_h, above, protrusion * under ** 0.8)
    profile *= _smoothstep(_T["n"] + 14.0, _T["n"] - 2.0, h0)
    width = np.where(h0 >= tip_h, 6.0 + 4.0 * t ** 1.5, 10.0)
    r += profile * np.exp(-((a / width) ** 2) * 1.1)
    r += 1.5 * _gauss((h0 - (tip_h + 1.0)) / 4.0) * _gauss(a / 6.0)  # tip lobule
    alae = _gauss((a - (F.nose_half - 5.5)) / 4.2) * _gauss((h0 - (_T["sn"] + 4.5)) / 3.6)
    r += 8.0 * alae
    groove = _gauss((np.hypot((a - (F.nose_half - 4.0)) / 1.0, (h0 - (_T["sn"] + 4.0)) / 0.9) - 6.3) / 0.9)
    r -= 1.2 * groove * (a > F.nose_half - 4.0)
    r -= 6.0 * F.nostrils(h0, s0)
    # Philtrum.
    r -= 0.8 * _gauss(s0 / 2.5) * _window(h0 - 0.5 * (_T["sn"] + _T["ls"]), 4.0, 7.0)
    # Lips.
    up, sto, lo = F.lips(s0)
    lip_w = _window(a / F.mouth_half, 0.75, 1.02)
    fl = p["lip_fullness"]
    upper = np.clip((h0 - sto) / np.maximum(up - sto, 0.5), 0.0, 1.0)
    lower = np.clip((sto - h0) / np.maximum(sto - lo, 0.5), 0.0, 1.0)
    r += fl * lip_w * np.sin(np.pi * upper) ** 0.7 * (h0 > sto) * 1.0
    r += (fl + 0.6) * lip_w * np.sin(np.pi * lower) ** 0.7 * (h0 <= sto)
    r += 1.5 * _gauss((h0 - up) / 2.0) * lip_w  # vermilion border ridge
    r -= 2.2 * _gauss((h0 - sto) / 0.7) * _window(a / F.mouth_half, 0.95, 1.05)  # mouth line
    r -= 1.2 * _gauss((np.hypot(a - F.mouth_half, h0 - sto) - 2.0) / 1.5)  # commissures
    # Nasolabial folds: from beside the alae down to beside the mouth corners.
    tl = np.clip((_T["sn"] + 6.0 - h0) / (_T["sn"] + 6.0 - (sto - 6.0)), 0.0, 1.0)
    fold_s = (F.nose_half + 3.0) + tl * (F.mouth_half + 6.0 - F.nose_half - 3.0)
    fold = _gauss((a - fold_s) / 2.2) * np.sin(np.pi * tl)
    r -= 1.4 * fold
    r += p["cheek_fullness"] * _smoothstep(fold_s, fold_s + 8.0, a) * _gauss((h0 - (_T["sto"] + 8.0)) / 18.0) * face
    # Cheekbones, chin, mentolabial sulcus, jaw angle, temples.
    r += p["cheekbone"] * _gauss((a - 50.0) / 14.0) * _gauss((h0 + 18.0) / 10.0)
    r += p["chin"] * _gauss(s0 / 15.0) * _gauss((h0 - (_T["gn"] + 11.0)) / 8.0)
    r -= 1.5 * _gauss(s0 / 12.0) * _gauss((h0 - (lo - 6.0)) / 3.5)
    r += 2.0 * _gauss((a - 78.0) / 10.0) * _gauss((h0 - (_T["gn"] + 25.0)) / 10.0)
    r -= 3.0 * _gauss((a - 82.0) / 10.0) * _gauss((h0 - 22.0) / 12.0)
    return r


def albedo_template(h0, s0):
    """Per-vertex region masks (smooth, in [0, 1]) for colouring: dict name -> (M,)."""
    a = np.abs(s0)
    up, lo = F.lids(s0)
    lip_up, sto, lip_lo = F.lips(s0)
    lips = (_smoothstep(lip_lo - 0.6, lip_lo + 0.6, h0) * (1.0 - _smoothstep(lip_up - 0.6, lip_up + 0.6, h0))
            * _window(a / F.mouth_half, 0.92, 1.0))
    b_lo, b_hi, b_w = F.brow(s0)
    brows = _smoothstep(b_lo - 1.0, b_lo + 0.5, h0) * (1.0 - _smoothstep(b_hi - 0.5, b_hi + 1.0, h0)) * b_w
    iris_d = np.hypot(h0 - F.eye_h, a - F.eye_c)
    return {
        "eyes": F.eye_mask(h0, s0, soften=0.3),
        "iris": 1.0 - _smoothstep(5.2, 6.0, iris_d),
        "pupil": 1.0 - _smoothstep(1.8, 2.4, iris_d),
        "lash": _gauss((h0 - up) / 0.6) * _window(F.eye_t(s0), 0.9, 1.05),
        "mouth_line": _gauss((h0 - sto) / 0.7) * _window(a / F.mouth_half, 0.85, 1.02),
        "lips": lips,
        "brows": brows,
        "nostrils": F.nostrils(h0, s0),
        "beard": F.beard(h0, s0) * (1.0 - lips),
        "hair": _smoothstep(F.hairline(s0) - 2.0, F.hairline(s0) + 4.0, h0),
        "cheeks": _gauss((a - 42.0) / 14.0) * _gauss((h0 + 25.0) / 12.0),
    }


def albedo(q: dict, masks: dict) -> np.ndarray:
    """Linear-RGB diffuse albedo from colour parameters ``q`` and region masks."""
    # Skin: interpolate log-albedo between light and dark skin by melanin level.
    light, dark = np.log([0.62, 0.43, 0.34]), np.log([0.20, 0.11, 0.07])
    skin = np.exp(light + q["melanin"] * (dark - light))
    skin = skin * np.array([1.0, 1.0 - 0.08 * q["redness"], 1.0 - 0.12 * q["redness"]])
    c = np.broadcast_to(skin, masks["eyes"].shape + (3,)).copy()
    cheeks = masks["cheeks"][:, None] * q["flush"]
    c *= 1.0 - cheeks * np.array([0.0, 0.12, 0.14])
    hair = np.asarray(q["hair"])
    beard = (q["beard"] * masks["beard"])[:, None]
    c = c * (1.0 - beard) + (c * 0.55 + 0.45 * hair * 0.5) * beard
    lips = skin * np.array([0.85, 0.55, 0.55]) * q["lip"]
    c = _mix(c, lips, masks["lips"])
    c = _mix(c, c * 0.3, 0.8 * masks["mouth_line"])
    c = _mix(c, hair * 0.9 + c * 0.1, 0.85 * masks["brows"])
    c = _mix(c, hair, masks["hair"])
    c = _mix(c, np.array([0.05, 0.03, 0.03]), 0.7 * masks["nostrils"])
    eye = np.broadcast_to(np.array([0.62, 0.58, 0.55]), c.shape).copy()
    eye = _mix(eye, np.asarray(q["iris"]), masks["iris"])
    eye = _mix(eye, np.array([0.015, 0.015, 0.015]), masks["pupil"])
    eye = _mix(eye, np.array([0.03, 0.025, 0.02]), masks["lash"])
    c = _mix(c, eye, masks["eyes"])
    c = _mix(c, c * 0.35, 0.8 * masks["lash"] * (1.0 - masks["eyes"]))
    return np.clip(c, 0.005, 0.95)


def _mix(a, b, t):
    t = np.asarray(t)[:, None] if np.ndim(t) == 1 else t
    return a * (1.0 - t) + b * t


def individual(rng: np.random.Generator, male: bool) -> tuple[dict, dict]:
    """Draw one individual's measurements and colours."""
    size_v, size_h = rng.standard_normal(2)  # common factors: vertical and horizontal size
    p = {}
    for k, (f, m, sd) in FARKAS.items():
        common = size_h if k in ("zy_zy", "go_go", "ft_ft", "en_en", "ex_ex", "al_al", "ch_ch") else size_v
        p[k] = (m if male else f) + sd * (0.55 * common + np.sqrt(1 - 0.55 ** 2) * rng.standard_normal())
    for k, (f, m, sd) in DEPTHS.items():
        p[k] = (m if male else f) + sd * rng.standard_normal()
    hair_tone = rng.beta(1.5, 2.5)  # 0 black, 1 blond
    iris_tone = rng.beta(1.2, 1.8)  # 0 brown, 1 blue-grey
    q = {
        "melanin": float(np.clip(rng.beta(1.6, 3.2), 0.0, 1.0)),
        "redness": rng.normal(0.5, 0.25),
        "flush": max(rng.normal(0.5, 0.3), 0.0),
        "lip": rng.normal(1.0, 0.08),
        "hair": (1.0 - hair_tone) * np.array([0.02, 0.015, 0.012]) + hair_tone * np.array([0.35, 0.25, 0.13]),
        "iris": (1.0 - iris_tone) * np.array([0.10, 0.05, 0.025]) + iris_tone * np.array([0.16, 0.22, 0.28]),
        "beard": float(np.clip(rng.normal(0.35, 0.15), 0.0, 0.7)) if male else 0.0,
    }
    q["hair"] = q["hair"] * (1.0 - 0.6 * q["melanin"])
    return p, q


def face_vertices(p: dict, h0: np.ndarray, phi0: np.ndarray, expression: dict | None = None) -> np.ndarray:
    """Vertex positions (M, 3) of the face with measurements ``p`` at template points."""
    s0 = R0 * phi0
    h, s = _warp(p, h0, s0)
    if expression:
        h, s = _expression_warp(expression, h0, s0, h, s)
    phi = s / R0
    r = _radius(p, h0, s0, phi)
    return np.stack([r * np.sin(phi), h, r * np.cos(phi)], axis=1)


#: The expression blendshapes of the built-in model (unit weight = a full expression).
EXPRESSIONS = ("smile", "brow_raise", "frown")


def _expression_warp(e: dict, h0, s0, h, s):
    a = np.abs(s0)
    sm = e.get("smile", 0.0)
    if sm:
        corner = _gauss(np.hypot(a - F.mouth_half, h0 - _T["sto"]) / 14.0)
        h = h + 4.0 * sm * corner
        s = s + np.sign(s0) * 4.0 * sm * corner
        h = h + 2.5 * sm * _gauss((a - 42.0) / 12.0) * _gauss((h0 + 28.0) / 12.0)  # cheeks rise
    br = e.get("brow_raise", 0.0)
    if br:
        h = h + 5.0 * br * _gauss((h0 - (_T["n"] + 9.0)) / 14.0) * _window(a, 45.0, 75.0) * (h0 > F.eye_h + 4.0)
    fr = e.get("frown", 0.0)
    if fr:
        band = _gauss((h0 - (_T["n"] + 8.0)) / 8.0) * _window(a, 40.0, 70.0)
        h = h - 3.0 * fr * band * (h0 > F.eye_h + 4.0)
        s = s - np.sign(s0) * 3.0 * fr * band * _window(a, 20.0, 45.0)
    return h, s


def landmark_vertices(grid: Grid) -> np.ndarray:
    """iBUG 68 landmarks: template positions (h0, s0) snapped to the nearest grid vertex."""
    ec, eh = F.eye_c, F.eye_half
    pts = {}
    # 1-17: jaw contour from the right ear (image left, -x) to the left.
    ang = np.linspace(-1.0, 1.0, 17)
    for i, t in enumerate(ang):
        pts[1 + i] = (-10.0 + (_T["gn"] + 10.0) * np.cos(t * np.pi / 2) ** 1.4, 75.0 * np.sin(t * np.pi / 2)
                      * (1.0 if abs(t) > 0 else 0.0))
    pts[9] = (_T["gn"], 0.0)
    # 18-27: eyebrows (lower-middle of the band), subject's right (-s) first, outer to inner.
    for i, frac in enumerate(np.linspace(1.0, -0.85, 5)):
        a = F.eye_c + 1.0 + 22.0 * frac
        lo, hi, _ = F.brow(np.array([a]))
        pts[18 + i] = (float(0.5 * (lo[0] + hi[0])), -a)
        pts[27 - i] = (float(0.5 * (lo[0] + hi[0])), a)
    # 28-31: nose bridge down to the tip; 32-36: nose base.
    for i, hh in enumerate(np.linspace(_T["n"], _T["prn"], 4)):
        pts[28 + i] = (hh, 0.0)
    for i, ss in enumerate([-F.nose_half + 4.5, -5.0, 0.0, 5.0, F.nose_half - 4.5]):
        pts[32 + i] = (_T["sn"] + (1.0 if i in (0, 4) else 0.0) + (0.8 if i in (1, 3) else 0.0), ss)
    # 37-48: eyes, each from the outer corner clockwise in the image.
    for side, base in ((-1, 37), (1, 43)):
        ts = [1.0, 0.35, -0.35, -1.0, -0.35, 0.35] if side < 0 else [-1.0, -0.35, 0.35, 1.0, 0.35, -0.35]
        for i, t in enumerate(ts):
            up, lo = F.lids(np.array([ec + t * eh]))
            hh = F.eye_h if abs(t) == 1.0 else (up[0] if i in (1, 2) else lo[0])
            pts[base + i] = (float(hh), side * (ec + t * eh * 0.97))
    # 49-60 outer lips, 61-68 inner lips (mouth corners first, image left to right).
    def lip(s, which):
        up, sto, lo = F.lips(np.array([s]))
        return float({"up": up, "sto": sto, "lo": lo}[which][0])

    mh = F.mouth_half
    outer = [(-mh, "sto"), (-0.6 * mh, "up"), (-0.2 * mh, "up"), (0.0, "up"), (0.2 * mh, "up"),
             (0.6 * mh, "up"), (mh, "sto"), (0.6 * mh, "lo"), (0.2 * mh, "lo"), (0.0, "lo"),
             (-0.2 * mh, "lo"), (-0.6 * mh, "lo")]
    for i, (s, w) in enumerate(outer):
        # On the vermilion border, 0.8 mm inside the lip so the landmark's vertex is a lip vertex.
        pts[49 + i] = (lip(0.97 * s, w) + {"up": -0.8, "lo": 0.8, "sto": 0.0}[w], s)
    inner = [(-0.85 * mh, "sto"), (-0.35 * mh, "sto"), (0.0, "sto"), (0.35 * mh, "sto"), (0.85 * mh, "sto"),
             (0.35 * mh, "sto"), (0.0, "sto"), (-0.35 * mh, "sto")]
    for i, (s, w) in enumerate(inner):
        pts[61 + i] = (lip(s, w) + (0.6 if i in (1, 2, 3) else (-0.6 if i > 4 else 0.0)), s)
    rows = np.array([pts[k][0] for k in range(1, 69)])
    cols = np.array([pts[k][1] for k in range(1, 69)]) / R0
    i = np.clip(np.round((H_MAX - rows) / (grid.h[0] - grid.h[1])).astype(int), 0, len(grid.h) - 1)
    j = np.clip(np.round((cols + PHI_MAX) / (grid.phi[1] - grid.phi[0])).astype(int), 0, len(grid.phi) - 1)
    return np.stack([np.arange(1, 69), i * len(grid.phi) + j], axis=1).astype(np.int32)


def region_map(shape=REGION_MAP_SHAPE) -> np.ndarray:
    """Label image over the template's (u, v) = (phi0, h0) texture space."""
    hgt, wid = shape
    v = (np.arange(hgt) + 0.5) / hgt
    u = (np.arange(wid) + 0.5) / wid
    h0 = (H_MAX - v * (H_MAX - H_MIN))[:, None] * np.ones((1, wid))
    s0 = (R0 * (-PHI_MAX + u * 2 * PHI_MAX))[None, :] * np.ones((hgt, 1))
    m = albedo_template(h0.ravel(), s0.ravel())
    labels = np.full(h0.size, REGIONS["skin"], np.uint8)
    for name, key in (("beard", "beard"), ("hair", "hair"), ("eyebrows", "brows"), ("lips", "lips"),
                      ("nostrils", "nostrils"), ("eyes", "eyes")):
        labels[m[key] > 0.5] = REGIONS[name]
    return labels.reshape(hgt, wid)
