"""Submodels: the processes that change the droplet set, each acting at the coupled step's event points.

One small interface, after HOOMD-blue's updaters: a :class:`Submodel` acts on the :class:`fulldem.stepper.Simulation`
at the step's start, before anything is deposited (:meth:`Submodel.at_start`: the feed inserts droplets there), and
at the end-of-step event point, after the drag owed to the fluid is deposited (:meth:`Submodel.at_end`: merges,
exits; the reaction's re-created droplets will go there too). Between those points the droplet set is fixed (the
step refuses a change; see :mod:`fulldem.stepper`). Droplets change only through their owner,
:class:`fulldem.droplets.DropletStore`; a submodel that proposes merges during the step calls
:meth:`fulldem.stepper.Simulation.propose_merges` and :class:`Merges` applies them; one that merges at an event
point calls :meth:`fulldem.stepper.Simulation.merge`, the one merge path, which also counts the merges.

A run's submodels come from :func:`submodels_for`, in the order they act: the built-in ones (feed, merges, exits)
and those the case switches on (``[coalescence] enabled``, ``[reaction] enabled``; :data:`CASE_SUBMODELS`). A new
submodel is a subclass here and an entry in :data:`CASE_SUBMODELS`.
"""

from __future__ import annotations

import importlib


class Submodel:
    """A process acting on a simulation at the step's event points (both hooks do nothing by default)."""

    name = "submodel"

    def at_start(self, sim) -> None:
        """At the step's start, before the first deposit (droplets added here are in this step)."""

    def at_end(self, sim) -> None:
        """At the end-of-step event point, after the owed drag is deposited."""

    def columns(self, sim) -> dict:
        """The submodel's own columns of the time-series row (names of :data:`settler.output.TIME_SERIES`), now."""
        return {}


class Feed(Submodel):
    """Inserts the droplets due by the case's feed schedule over the inlet (when the simulation's feed is on)."""

    name = "feed"

    def at_start(self, sim) -> None:
        if sim.feed_on:
            sim.insert(sim.schedule.advance(sim.time + sim.dt))


class Merges(Submodel):
    """Merges the pairs proposed during the step (:meth:`fulldem.stepper.Simulation.propose_merges`)."""

    name = "merges"

    def at_end(self, sim) -> None:
        sim.apply_merges()


class Exits(Submodel):
    """Removes droplets touching an absorbing bottom (settled) or crossing the outlet disk (lost)."""

    name = "exits"

    def at_end(self, sim) -> None:
        sim.remove_exits()


#: Submodels switched on by a case section's ``enabled`` key: section -> "module:Class" of the submodel (constructed
#: with the case; named, not imported, so that a submodel's module may import this one), or None where the engine
#: does not have it yet (a run then says so; see fulldem.driver).
CASE_SUBMODELS: dict[str, str | None] = {"coalescence": "fulldem.submodels.coalescence:Coalescence",
                                         "reaction": "fulldem.submodels.reaction:Reaction"}


def submodel_class(section: str) -> type[Submodel]:
    """The submodel class switched on by case section ``section`` (:data:`CASE_SUBMODELS`)."""
    module, name = CASE_SUBMODELS[section].split(":")
    return getattr(importlib.import_module(module), name)


def missing_submodels(case) -> list[str]:
    """The case's switched-on submodels that the engine does not have yet."""
    return [name for name, spec in CASE_SUBMODELS.items() if spec is None and getattr(case, name).enabled]


def submodels_for(case) -> list[Submodel]:
    """The submodels of a run of ``case``, in the order they act at each event point: feed (start), merges, the
    case's switched-on submodels, exits (end)."""
    chosen = [submodel_class(name)(case) for name, spec in CASE_SUBMODELS.items()
              if spec is not None and getattr(case, name).enabled]
    return [Feed(), Merges(), *chosen, Exits()]
