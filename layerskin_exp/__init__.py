"""layerskin-exp: experiments with a two-layer FSR e-skin, on the bench or on its simulated twin."""

__version__ = "0.2.0"
