"""Published optical constants of the face's materials, the one table the
plugins' ground truth, the simulator and the fitters read.

Sources of the relative indices of refraction η (at visible wavelengths):

* skin (and lips, nostrils, beard, which the a-priori regions count as
  skin): 1.38, Weyrich et al., "Analysis of human faces using a
  measurement-based skin reflectance model", SIGGRAPH 2006, sec. 5;
* the cornea (region ``eyes``): 1.376, Le Grand's schematic eye (Atchison &
  Smith, "Optics of the Human Eye", 2000);
* hair keratin (regions ``hair`` and ``eyebrows``): 1.55, Marschner et al.,
  "Light scattering from human hair fibers", SIGGRAPH 2003.
"""

from __future__ import annotations

#: Relative index of refraction η per face region (see the module docstring).
REFRACTIVE_INDEX: dict[str, float] = {"skin": 1.38, "lips": 1.38, "nostrils": 1.38, "beard": 1.38,
                                      "eyes": 1.376, "eyebrows": 1.55, "hair": 1.55}

#: η of skin, the value a fit holds when it knows no region.
SKIN_REFRACTIVE_INDEX = REFRACTIVE_INDEX["skin"]

__all__ = ["REFRACTIVE_INDEX", "SKIN_REFRACTIVE_INDEX"]
