"""The ``lafortune`` BSDF plugin (generalised cosine lobes + Lambert)."""


from mifaces.brdf.lafortune import Lafortune, lobe_names

from .analytic import AnalyticBSDF, _value_is_zero, plugin_docstring


def _lobes_in(props) -> list[int]:
    """Lobe numbers given in ``props``: 1, plus every j with ``cxy_j``,
    ``cz_j`` or ``exponent_j``."""
    lobes = {1}
    for key in props.keys():
        for prefix in ("cxy_", "cz_", "exponent_"):
            if key.startswith(prefix) and key[len(prefix):].isdigit():
                lobes.add(int(key[len(prefix):]))
    return sorted(lobes)


class LafortuneBSDF(AnalyticBSDF):
    @classmethod
    def make_model(cls, props):
        return Lafortune(lobes=_lobes_in(props))

    def __init__(self, props):
        self.all_lobes = None
        AnalyticBSDF.__init__(self, props)

    def _specular_active(self) -> bool:
        # Evaluate only the lobes whose coefficients are not all zero.
        if self.all_lobes is None:
            self.all_lobes = self.model.lobes
        active = []
        for j in self.all_lobes:
            cxy, cz, _ = lobe_names(j)
            if not (_value_is_zero(self.values[cxy]) and _value_is_zero(self.values[cz])):
                active.append(j)
        if active:
            self.model = Lafortune(lobes=active)
        return bool(active)


LafortuneBSDF.__doc__ = plugin_docstring(
    Lafortune(lobes=2), "Lafortune BSDF (``<bsdf type=\"lafortune\">``), one or more lobes.", """\
    <bsdf type="lafortune">
        <rgb name="diffuse_reflectance" value="0.45, 0.3, 0.25"/>
        <float name="cxy" value="-0.95"/>
        <float name="cz" value="0.95"/>
        <float name="exponent" value="30"/>
        <float name="cxy_2" value="0.2"/>  <!-- a second, retro-reflective lobe -->
        <float name="cz_2" value="0.3"/>
        <float name="exponent_2" value="2"/>
    </bsdf>""")

PLUGIN = LafortuneBSDF
