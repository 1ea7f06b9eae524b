"""Mitsuba 3: renders of built-in exact scenes or XML files (``render``) and its BSDF,
microfacet and emitter samplers as batch sample/pdf pairs for the sampler checks
(``samplers``).  Mitsuba is imported only when one of them is used."""
