"""The processes that change the droplet set or the droplets' sizes at the step's event points.

What belongs here: the submodel interface and the feed, merge and exit submodels (:mod:`.base`), the feed's placement
over the inlet (:mod:`.feed`), the exits at the bottom and the outlet (:mod:`.exits`), coalescence
(:mod:`.coalescence`) and the reaction (:mod:`.reaction`). A submodel proposes changes; the droplet store
(:mod:`fulldem.droplets`) applies them at the event point that :mod:`fulldem.stepper` documents. The droplet laws
they evaluate (coalescence probability, reaction fits) are :mod:`settler.physics`'s, shared with popbal.
"""
