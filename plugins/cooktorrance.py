"""The ``cooktorrance`` BSDF plugin (Beckmann microfacet lobe + Lambert)."""

from mifaces.brdf.cooktorrance import CookTorrance

from .analytic import AnalyticBSDF, plugin_docstring


class CookTorranceBSDF(AnalyticBSDF):
    @classmethod
    def make_model(cls, props):
        return CookTorrance(fresnel=props.get("fresnel", "dielectric"),
                            geometry=props.get("geometry", "vcavity"))


CookTorranceBSDF.__doc__ = plugin_docstring(
    CookTorrance(), "Cook-Torrance BSDF (``<bsdf type=\"cooktorrance\">``).", """\
    <bsdf type="cooktorrance">
        <rgb name="diffuse_reflectance" value="0.45, 0.3, 0.25"/>
        <rgb name="specular_reflectance" value="1.0"/>
        <float name="roughness" value="0.3"/>
        <float name="eta" value="1.4"/>
        <string name="fresnel" value="dielectric"/>
        <string name="geometry" value="vcavity"/>
    </bsdf>""")

PLUGIN = CookTorranceBSDF
