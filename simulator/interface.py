"""The port's optical interfaces as a Mitsuba BSDF: smooth refraction without reflection.

Each face of the port is a smooth dielectric interface. Light reflected at the port (about 4 %
per face) leaves towards the housing or back into the water and, in a dark housing, never
reaches the sensor, so the camera sees only the transmitted part. Mitsuba's ``dielectric``
chooses reflection or transmission at random, which leaves a few percent of samples black and
makes the raw image noisy; this BSDF always refracts and weights the path by the Fresnel
transmittance (unpolarised) and the radiance scaling ``(n_i / n_t)^2`` between media. It is
unbiased for a scene where the reflected light carries nothing; the neglected second-order ghost
(two internal reflections, about 0.2 %) is the only difference to the full physics.
"""

from __future__ import annotations

from types import ModuleType

__all__ = ["INTERFACE", "register"]

INTERFACE = "lfsim_interface"


def register(mi: ModuleType) -> None:
    """Define and register the interface BSDF for the current Mitsuba variant."""
    import drjit as dr

    class InterfaceBSDF(mi.BSDF):
        """Refract-only smooth interface; ``int_ior`` behind the normal, ``ext_ior`` in front."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.int_ior = float(props["int_ior"])
            self.ext_ior = float(props["ext_ior"])
            self.eta = self.int_ior / self.ext_ior
            flags = mi.BSDFFlags.DeltaTransmission | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            self.m_components = [flags]
            self.m_flags = flags

        def sample(self, ctx, si, sample1, sample2, active=True):
            cos_theta_i = mi.Frame3f.cos_theta(si.wi)
            r_i, cos_theta_t, eta_it, eta_ti = mi.fresnel(cos_theta_i, self.eta)
            bs = mi.BSDFSample3f()
            bs.wo = mi.refract(si.wi, cos_theta_t, eta_ti)
            bs.pdf = mi.Float(1.0)
            bs.eta = eta_it
            bs.sampled_component = mi.UInt32(0)
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DeltaTransmission)
            scale = (1.0 - r_i) * dr.select(ctx.mode == mi.TransportMode.Radiance, dr.square(eta_ti), 1.0)
            tir = r_i >= 1.0
            return bs, dr.select(tir | ~active, mi.Spectrum(0.0), mi.Spectrum(scale))

        def eval(self, ctx, si, wo, active=True):
            return mi.Spectrum(0.0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return mi.Spectrum(0.0), mi.Float(0.0)

        def to_string(self):
            return f"InterfaceBSDF[int_ior={self.int_ior}, ext_ior={self.ext_ior}]"

    mi.register_bsdf(INTERFACE, lambda props: InterfaceBSDF(props))
