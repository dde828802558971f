"""The layered stack's linear response (layerskin_exp/sim/layered.py) against closed forms and the
balances any stack must satisfy."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.layered import Layer, Stack, line_load_response, section_stack


def test_a_deep_layer_is_the_half_space():
    """A 60 mm layer on the rigid base, read within 2 mm of its surface at xi >= 0.5 / mm: the
    half-space's transfers, (1 + xi z) e^-xi z for a pressure and -xi z e^-xi z for a shear
    (Flamant's and Cerruti's line loads in the wavenumber domain)."""
    st = Stack((Layer.isotropic("solid", 60.0, 1.0, 0.3),))
    xi = np.array([0.5, 1.0, 2.0, 5.0, 10.0, 40.0])
    z = np.array([0.05, 0.3, 1.0, 2.0])
    tr = st.transfer(xi, z)
    xz = xi[None, :] * z[:, None]
    np.testing.assert_allclose(tr["normal"], (1 + xz) * np.exp(-xz), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(tr["shear"], -xz * np.exp(-xz), rtol=1e-6, atol=1e-12)


@pytest.fixture(scope="module")
def skin():
    return section_stack(SimConfig())


def test_every_plane_of_the_skin_carries_the_load_and_its_moment(skin):
    """At long wavelengths every plane carries the whole pressure (transfer -> 1) and the shear's
    couple about itself (transfer / xi -> -z: the moment balance of the stack above the plane),
    whatever the layers: the cover, the stiff films, the soft lattice."""
    depths = [0.1, skin.depth_of("core"), skin.depth_of("lattice", 0.5), skin.depth_of("deep_core")]
    xi = np.array([1e-5])
    tr = skin.transfer(xi, depths)
    np.testing.assert_allclose(tr["normal"][:, 0], 1.0, rtol=1e-6)
    np.testing.assert_allclose(tr["shear"][:, 0] / xi[0], -np.array(depths), rtol=1e-3)


def _contact(x):
    return np.where(np.abs(x) < 0.6, 40.0 * np.sqrt(np.clip(1 - (x / 0.6) ** 2, 0, None)), 0.0)  # kPa


def test_line_loads_conserve_force_at_each_plane_of_the_skin(skin):
    """Through the FFT path: a contact-like pressure and shear on the cover give, at the superficial
    core and the deep core, profiles whose integral is the applied force (the shear adds none)."""
    dx = 0.02
    x = np.arange(-150.0, 150.0, dx)  # the bonded sheet's basin reaches tens of mm: keep all of it
    p = _contact(x)
    depths = [skin.depth_of("core"), skin.depth_of("deep_core")]
    normal = line_load_response(skin, x, p, None, depths)
    sheared = line_load_response(skin, x, p, p / 3.0, depths) - normal
    force = p.sum() * dx
    np.testing.assert_allclose(normal.sum(axis=1) * dx, force, rtol=1e-6)
    np.testing.assert_allclose(sheared.sum(axis=1) * dx, 0.0, atol=1e-6 * force)
    # the superficial core reads the contact spread by the stack above it: lower peak, wider
    assert normal[0].max() < p.max() and normal[0][np.abs(x - 1.0) < dx / 2].item() > 0.02 * p.max()


def test_a_line_shear_tilts_each_plane_by_its_depth():
    """The first moment of the normal stress a shear traction Q puts on a plane at depth z is Q z
    (the stack above the plane balances its moment), read from the profiles (a cover on a soft
    layer, whose fields stay within the window; the skin's in-plane-stiff sheet carries part of
    the couple over metres, which only its long-wavelength limit shows, checked above)."""
    st = Stack((Layer.isotropic("cover", 0.2, 0.035, 0.49), Layer.isotropic("soft", 5.0, 0.01, 0.3)))
    dx = 0.02
    x = np.arange(-100.0, 100.0, dx)
    q = _contact(x) / 3.0
    depths = np.array([0.1, 0.2, 1.0, 3.0])
    sheared = line_load_response(st, x, np.zeros_like(x), q, depths)
    np.testing.assert_allclose((sheared * x).sum(axis=1) * dx, q.sum() * dx * depths, rtol=2e-3)
    assert (sheared[:, x > 0].sum(axis=1) > 0).all()  # compression ahead of the shear, tension behind


def test_bad_input_is_refused_naming_it(skin):
    with pytest.raises(ValueError, match="wavenumbers"):
        skin.transfer(np.array([0.0, 1.0]), [0.1])
    with pytest.raises(ValueError, match="outside the stack"):
        skin.transfer(np.array([1.0]), [skin.thickness_mm + 1.0])
    with pytest.raises(KeyError, match="no layer 'nope'"):
        skin.depth_of("nope")
