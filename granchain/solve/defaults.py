"""The integrator a chain is integrated with when none is given, by what the chain is like.

A chain family names, for each chain it builds, the chain's *character* (``ChainFamily.character``): what
sets the integrator's step and where its error goes, which decided the validated method and tolerances:

- :data:`LIGHT_GRANULES`: light granules between heavy ones (the paper's decorated chains) set the step.
  ``RKN4.windowed`` at :data:`ENSEMBLE_RTOL`, :data:`ENSEMBLE_ATOL` (``DP5.relaxed`` at :data:`DAMPED_RTOL`,
  :data:`DAMPED_ATOL` for contacts whose forces depend on velocities).
- :data:`SMOOTH`: masses that change slowly along the chain, no light granules (the effective chains):
  long steps whose error accumulates along the chain. ``DP5.windowed`` at :data:`SMOOTH_RTOL`,
  :data:`SMOOTH_ATOL`.
- :data:`REFLECTING`: masses that jump at random (polydisperse and binary chains, a user's own): waves
  reflected at every jump give granules their largest velocity after the front has passed, so no relaxed
  zone. ``DP5`` at :data:`RANDOM_RTOL`, :data:`RANDOM_ATOL`.

The character, not the chain's name, picks the default: a user's family whose chains are called
"decorated" is not integrated as the paper's decorated chains unless it says that it is like them.
"""

from __future__ import annotations

from .integrators import DP5, RKN4, Integrator

__all__ = ["LIGHT_GRANULES", "SMOOTH", "REFLECTING", "CHARACTERS", "default_integrator", "ENSEMBLE_RTOL", "ENSEMBLE_ATOL",
           "SMOOTH_RTOL", "SMOOTH_ATOL", "RANDOM_RTOL", "RANDOM_ATOL", "DAMPED_RTOL", "DAMPED_ATOL"]

#: Light granules between heavy ones set the step (decorated chains).
LIGHT_GRANULES = "light granules"
#: Masses that change slowly, no light granules (effective chains).
SMOOTH = "smooth"
#: Masses that jump at random along the chain (polydisperse, binary and users' chains).
REFLECTING = "reflecting"
#: The characters a family may give its chains.
CHARACTERS = (LIGHT_GRANULES, SMOOTH, REFLECTING)

#: The defaults of the three characters: the relaxed zone behind the pulse and the trailing window (:meth:`DP5.windowed`;
#: :meth:`DP5.relaxed`, every granule to the end, with ``pulse_window="full"``), with the
#: Runge-Kutta-Nystrom pair :class:`RKN4` at ENSEMBLE_RTOL / ENSEMBLE_ATOL for decorated chains and DP5
#: at SMOOTH_RTOL / SMOOTH_ATOL for their effective chains; DP5 at RANDOM_RTOL / RANDOM_ATOL without the
#: relaxed zone for every other chain kind (polydisperse, binary, a user's).
#: Per-realisation peaks then stay within 1e-6 (relative; times within 1e-5) of DOP853 at rtol 1e-10
#: (tests/test_window.py), far below the ensemble's statistical error (~1e-3 for 30,000
#: realisations). Why two: in a decorated chain the light granules' oscillations set the step; RKN4
#: takes ~0.9x DP5's steps there at half the force evaluations each (1.3-1.5x less time per N = 26
#: realisation), with peak velocities as accurate as DP5's at rtol 1e-6 (at the free end of N = 6 chains
#: more: in the 5 realisations of the paper's set checked where DP5 missed DOP853 by 1.2e-6 to 1.9e-6,
#: within 6e-8); its peak contact forces set its tolerance (see ``RKN4.goal_tolerances``).
#: A chain without light granules takes long steps, its error accumulates along the chain and it needs
#: a tight tolerance (DP5 at rtol 1e-6 puts its peaks up to ~5e-6 off); there a 4th-order method
#: gains nothing.
#:
#: Each tolerance is the loosest tried whose worst error stays within half the contract, on the chains
#: of ``benchmarks/validate_tolerances.py`` (2026-11-27): 100 random N = 26 chains (and, decorated, the
#: paper set's two stored worst cases) against DOP853 at rtol 1e-12, and 2,000 more against exact DP5
#: at rtol 1e-10 / 1e-11 (the tail: the worst of 2,000 chains was 1.2x to 3.3x the worst of 100).
#: Half, because the paper's set has 120,000 realisations of each kind, 57x the chains checked.
ENSEMBLE_RTOL, ENSEMBLE_ATOL = RKN4.goal_tolerances  # 3e-6, 3e-9 (1e-5, 1e-8 until 2026-11-27)
#: The effective chains' (``DP5.windowed``): their worst error is the last granule's peak velocity
#: (the free end), in rare chains and not smoothly in rtol. Worst fraction of the contract on the 100 /
#: 2,000 chains: rtol 5e-8 (the default until then) 0.86 / **1.58**, missed on 0 / 6 chains; 3e-8
#: 0.35 / 1.05; 2e-8 0.40 / 1.33; 1e-8 **0.21 / 0.44**; 5e-9 0.09 / 0.19. On the paper's own set (30,000
#: realisations at each N = 6, 11, 16, 26, the stored peaks against exact DP5 at rtol 1e-11) rtol 5e-8
#: missed the contract on 170 of the 120,000 realisations (up to 2.97x, all at the last granule's peak
#: velocity), rtol 1e-8 on none (worst 0.66, N = 6). Cost: 1.39x the steps of rtol 5e-8 (N = 26).
SMOOTH_RTOL = 1e-8
SMOOTH_ATOL = 1e-11
#: DP5's tolerances for the chain kinds other than the paper's two (random polydisperse and binary
#: chains, a user's family), integrated without the relaxed zone: waves reflected at every change of
#: mass give some granules their largest velocity after the front has moved on, where the relaxed zone
#: loosens the tolerance (``DP5.relaxed(5e-8, 5e-11)``, then the effective chains' default, missed the
#: peak-velocity contract by up to 18x and 54x on a quarter of 100 random polydisperse and binary chains
#: of 26 granules). At this rtol the worst of those chains is at 0.19 and 0.31 of the contract (1e-8: up
#: to 2.0x; 5e-9: up to 1.24x), for about twice the CPU (``benchmarks/validate_tolerances.py``,
#: 2026-11-25; not checked on the tail beyond those 100 chains).
RANDOM_RTOL = 2e-9
RANDOM_ATOL = 2e-12
#: DP5's tolerances for decorated chains with a viscoelastic contact law (RKN4 integrates x'' = f(x) only):
#: the rtol at which DP5's peak velocities matched RKN4's at rtol 1e-5 on elastic decorated chains. Not
#: validated on viscoelastic chains; on elastic ones ``DP5.windowed(1e-6)`` meets the contract with
#: less margin than the default RKN4 (worst 0.41 of it on the 102 chains of validate_tolerances, 0.67 on
#: the 2,000 more; rtol 3e-7: 0.21 / 0.23).
DAMPED_RTOL = 1e-6
DAMPED_ATOL = 1e-9


def default_integrator(character: str, *, conservative: bool = True, windowed: bool = True,
                       method: type | None = None) -> Integrator:
    """The integrator a chain of this ``character`` (:data:`CHARACTERS`) is integrated with in an ensemble
    unless one is given.

    - :data:`LIGHT_GRANULES`: ``RKN4.windowed()`` at :data:`ENSEMBLE_RTOL`, :data:`ENSEMBLE_ATOL`; for contacts
      that are not ``conservative`` (forces of velocities: RKN4 integrates x'' = f(x) only) ``DP5.relaxed`` at
      :data:`DAMPED_RTOL`, :data:`DAMPED_ATOL`, windowed or not: the granules behind the pulse keep rattling
      and dissipating until the end, and a granule the trailing window drops stops dissipating (9 % of the
      dissipated energy lost on a 40-granule chain: docs, "Real contacts").
    - :data:`SMOOTH`: ``DP5.windowed()`` at :data:`SMOOTH_RTOL`, :data:`SMOOTH_ATOL`.
    - :data:`REFLECTING`: ``DP5`` at :data:`RANDOM_RTOL`, :data:`RANDOM_ATOL`, without the relaxed zone.

    ``windowed``: the trailing window, with which a realisation costs linearly in the chain's length (the
    ensembles give each observed granule its averaged-pulse window); False: ``relaxed`` instead of
    ``windowed``, every granule integrated to the end of the time grid. ``method``: an adaptive
    Runge-Kutta class (``DP5``, ``RKN4``) to use instead of the character's, with the character's zones
    and tolerances (light granules: the method's own ``goal_tolerances``)."""
    if character not in CHARACTERS:
        raise ValueError(f"unknown chain character {character!r}: a family's chains are one of {list(CHARACTERS)}")
    zone = (lambda cls: cls.windowed) if windowed else (lambda cls: cls.relaxed)
    if character == LIGHT_GRANULES:
        if method is not None:
            return zone(method)()
        return zone(RKN4)(ENSEMBLE_RTOL, ENSEMBLE_ATOL) if conservative else DP5.relaxed(DAMPED_RTOL, DAMPED_ATOL)
    if character == SMOOTH:
        return zone(method or DP5)(SMOOTH_RTOL, SMOOTH_ATOL)
    return (method or DP5)(RANDOM_RTOL, RANDOM_ATOL)
