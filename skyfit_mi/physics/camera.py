"""The camera as a radiometric sensor (thesis chapter 5 and 6.3.3), NumPy.

Scene radiance L [W m^-2 sr^-1] becomes a pixel value V [DN] in these steps:

1. optics: image-plane irradiance E_p = l(alpha) L, with the optional off-axis falloff
   cos^4(alpha) of eq. 5.6 (the constant (pi/4)(D/f)^2 folded into the exposure);
2. exposure: normalised signal s = exposure * E_p, shutter, gain and aperture of eq. 5.11 in
   ``exposure`` [sr m^2 W^-1]; s = 1 is full scale;
3. saturation: s clipped to [0, 1];
4. response (eq. 5.11's transfer function Q): linear, s^(1/gamma), or the sRGB curve;
5. noise: additive Gaussian, ``noise_percent`` per cent of the dynamic range (thesis 6.3.3);
6. quantisation to ``bits`` bits, clipped to [0, 2^bits - 1].

Chi-square's per-pixel sigma (eq. 6.2) is sqrt(sigma_noise^2 + 1/12) DN (noise plus uniform
quantisation), plus a rendered frame's Monte Carlo error through the response.  Pixels at the
top (or bottom) code are censored (P(value >= top)) in chi-square; sigma is infinite only for
a pixel carrying no information.
"""

from dataclasses import asdict, dataclass

import numpy as np

from ..errors import SkyfitError, check_choice, check_range

#: Each response's transfer function Q(s) (eq. 5.11), its inverse and dQ/ds, as functions of
#: (x, gamma); sRGB's curve of IEC 61966-2-1.
CURVES = {
    "linear": (lambda s, g: s, lambda v, g: v, lambda s, g: np.ones_like(s)),
    "gamma": (lambda s, g: s ** (1.0 / g), lambda v, g: v ** g,
              lambda s, g: s ** (1.0 / g - 1.0) / g),
    "srgb": (lambda s, g: np.where(s <= 0.0031308, 12.92 * s, 1.055 * s ** (1 / 2.4) - 0.055),
             lambda v, g: np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4),
             lambda s, g: np.where(s <= 0.0031308, 12.92, 1.055 / 2.4 * s ** (1 / 2.4 - 1.0)))}
BIT_DEPTHS = (8, 10, 12, 16)
#: A code within this fraction of the largest (any channel) counts as clipped: a JPEG's ringing
#: leaves a clipped area's codes a few below the top (249-254.9 of 255).
CLIP_FRACTION = 0.97


def clipped(codes, max_code):
    """Where ``codes`` [DN] lie within :data:`CLIP_FRACTION` of ``max_code`` (NaN: False)."""
    with np.errstate(invalid="ignore"):
        return np.asarray(codes) >= CLIP_FRACTION * max_code


@dataclass(frozen=True)
class SensorModel:
    """A radiometric camera model (module docstring).

    Attributes
    ----------
    exposure : float
        Radiance giving a full-scale signal is 1/exposure [sr m^2 W^-1].
    response : {'linear', 'gamma', 'srgb'}
    gamma : float
        Exponent of the power-law response (V ~ s^(1/gamma)).
    bits : {8, 10, 12, 16}
    noise_percent : float
        Gaussian noise standard deviation, per cent of the dynamic range, in [0, 50].
    cos4 : bool
        Apply the cos^4 off-axis falloff of eq. 5.6.
    """

    exposure: float
    response: str = "linear"
    gamma: float = 2.2
    bits: int = 8
    noise_percent: float = 0.0
    cos4: bool = False

    def __post_init__(self):
        if not (np.isfinite(self.exposure) and self.exposure > 0):
            raise SkyfitError(f"sensor exposure = {self.exposure!r} must be a positive number "
                              "[sr m^2 W^-1] (1 / the radiance that saturates the sensor).")
        check_choice("sensor response", self.response, tuple(CURVES))
        check_range("sensor gamma", self.gamma, 0.1, 10.0)
        check_choice("sensor bit depth", self.bits, BIT_DEPTHS)
        check_range("sensor noise_percent", self.noise_percent, 0.0, 50.0, "%")

    @property
    def max_code(self):
        """Largest pixel value [DN]."""
        return 2 ** self.bits - 1

    @property
    def noise_sigma(self):
        """Standard deviation of the additive noise [DN]."""
        return self.noise_percent / 100.0 * self.max_code

    @property
    def sigma(self):
        """Standard deviation of an unsaturated pixel [DN] (noise + quantisation)."""
        return float(np.sqrt(self.noise_sigma ** 2 + 1.0 / 12.0))

    def to_dict(self):
        return asdict(self)

    # ---- the forward model ----------------------------------------------
    @staticmethod
    def falloff(width, height, fov_deg, pixels=None):
        """cos^4 of each pixel's off-axis angle (eq. 5.6) for a horizontal field of view: (H, W),
        or at ``pixels`` (P, 2) (x, y) alone, (P,)."""
        t = np.tan(np.radians(fov_deg) / 2.0)
        if pixels is None:
            x, y = np.arange(width)[None, :], np.arange(height)[:, None]
        else:
            x, y = np.asarray(pixels, dtype=float).T
        tx = ((x + 0.5) / width * 2.0 - 1.0) * t
        ty = ((y + 0.5) / height * 2.0 - 1.0) * t * height / width
        return (1.0 / (1.0 + tx ** 2 + ty ** 2)) ** 2      # cos^4 = 1/(1 + tan^2)^2

    def signal(self, radiance, fov_deg=None):
        """Normalised, unclipped sensor signal s for radiance (H, W, 3) [W m^-2 sr^-1]."""
        s = np.asarray(radiance, dtype=float) * self.exposure
        if self.cos4:
            if fov_deg is None:
                raise SkyfitError("the cos^4 falloff needs the camera's field of view (fov_deg).")
            h, w = s.shape[:2]
            s = s * self.falloff(w, h, fov_deg)[..., None]
        return s

    def respond(self, s):
        """Transfer function on the clipped signal, in [0, 1]."""
        return CURVES[self.response][0](np.clip(s, 0.0, 1.0), self.gamma)

    def linearise(self, values):
        """The signal s in [0, 1] that pixel ``values`` [DN] encode: eq. 5.11's Q^-1 on
        values / max_code, clipped."""
        v = np.clip(np.asarray(values, dtype=float) / self.max_code, 0.0, 1.0)
        return CURVES[self.response][1](v, self.gamma)

    def gain(self, width, height, fov_deg):
        """Per-pixel factor from radiance to signal, exposure x optional cos^4, shape (H, W)."""
        g = np.full((height, width), float(self.exposure))
        return g * self.falloff(width, height, fov_deg) if self.cos4 else g

    def slope(self, s):
        """d(response)/d(signal) at signal ``s``; 0 where the sensor is saturated or black."""
        s = np.asarray(s, dtype=float)
        inside = (s > 0.0) & (s < 1.0)
        d = CURVES[self.response][2](np.clip(s, 1e-12, 1.0), self.gamma)
        return np.where(inside, d, 0.0)

    def capture(self, radiance, rng, fov_deg=None, radiance_sd=None):
        """Simulate one exposure.

        Parameters
        ----------
        radiance : ndarray (H, W, 3)
            Scene radiance [W m^-2 sr^-1].
        rng : numpy.random.Generator
            Source of the noise (record its seed).
        fov_deg : float, optional
            Horizontal field of view, needed with ``cos4``.
        radiance_sd : ndarray (H, W, 3), optional
            Monte Carlo standard error of ``radiance`` [W m^-2 sr^-1], carried into sigma.

        Returns
        -------
        values, sigma : ndarray (H, W, 3), uint16 and float32
            Pixel values [DN] in [0, 2^bits - 1] (top code: saturated, censored) and their
            finite chi-square standard deviation [DN].
        """
        s = self.signal(radiance, fov_deg)
        v = self.respond(s) * self.max_code
        if self.noise_percent > 0:
            v = v + rng.normal(0.0, self.noise_sigma, size=v.shape)
        values = np.clip(np.rint(v), 0, self.max_code).astype(np.uint16)
        var = np.full(s.shape, self.sigma ** 2)
        if radiance_sd is not None:
            ds_dl = s / np.where(radiance > 0, radiance, 1.0)           # the pixel's gain
            # a clipped value is censored at the clip, where its Monte Carlo error still
            # spreads the signal: the slope just inside the range, not the flat beyond it
            inside = np.clip(s, 1e-9, 1.0 - 1e-9)
            var = var + (self.slope(inside) * self.max_code * ds_dl * radiance_sd) ** 2
        sigma = np.sqrt(var).astype(np.float32)
        return values, sigma
