"""The ``phong`` BSDF plugin (energy-normalised modified Phong)."""

from mifaces.brdf.phong import Phong

from .analytic import AnalyticBSDF, plugin_docstring


class PhongBSDF(AnalyticBSDF):
    @classmethod
    def make_model(cls, props):
        return Phong()


PhongBSDF.__doc__ = plugin_docstring(Phong(), "Modified Phong BSDF (``<bsdf type=\"phong\">``).", """\
    <bsdf type="phong">
        <rgb name="diffuse_reflectance" value="0.45, 0.3, 0.25"/>
        <rgb name="specular_reflectance" value="0.1"/>
        <float name="exponent" value="40"/>
    </bsdf>""")

PLUGIN = PhongBSDF
