"""Mitsuba 3: Mitsuba's process-wide state, the LLVM library and the variant lock
(``runtime``); renders of built-in exact scenes or XML files (``render``); samplers as batch
sample/pdf/eval triples: their base (``batch``), BSDFs and microfacet distributions
(``samplers``, also ``make_sampler`` for suites), phase functions (``phase``), environment
maps and area lights on shapes (``emitters``, checked through a map of their directions:
``views``, a rectangle's own square ``rectangle``, else the equal-area map of a cap ``cap``);
planted faults (``faults``); the failure-aware chi-square with the reported-pdf check, and the
weight check (``checks``); the catalogue of samplers they run on (``catalogue``).  Mitsuba is
imported only when one of them is used."""
