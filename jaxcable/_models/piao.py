"""Piao et al.'s five-element creep model ([`FiveElementModel`][]), one function per
equation of the paper:

- Eq. 1, one family (a spring and two Kelvin-Voigt elements) under a stress:
    [`family_step`][];
- Eq. 2-3, unloading as the superposition of an added negative stress on the
    unloading family, which removes at most what the loading family added (never
    shorter than new): `superposed_strain`;

and Piao's Table 1 (`PIAO_TABLE1`). The parameter surfaces (Eq. 5, Table 3) are in
`piao_surface.py`.
"""

import abc

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._cable import Cable
from .base import AbstractCableModel, StrainParts, state_zero
from .fields import MODULUS, VISCOSITY, parameter
from .kernels import kelvin_voigt_step, running_max


PIAO_TABLE1: dict[str, float] = dict(
    E_L2=9.5e9,
    E_L3=5.0e10,
    eta_L2=1.0e10,
    eta_L3=1.0e13,
    E_UL2=9.5e9,
    E_UL3=5.0e10,
    eta_UL2=1.0e10,
    eta_UL3=1.0e13,
)
"""Piao Table 1, the loading parameters that do not depend on payload or length
(E_L2, E_L3 in Pa, eta_L2, eta_L3 in Pa s), with the unloading ones (E_UL2, E_UL3,
eta_UL2, eta_UL3) set equal to them: the unloading table (Table 2) is lost."""


def table1_field(name: str):
    """A model parameter (a modulus, Pa, or a viscosity, Pa s) whose default is Piao's
    Table 1 value `name`."""
    facts = VISCOSITY if name.startswith("eta") else MODULUS
    return parameter(PIAO_TABLE1[name], **facts)


# One family's parameters, in the order of `family_step`: (E1, E2, eta2, E3, eta3).
ParameterSet = tuple[
    Float[Array, ""],
    Float[Array, ""],
    Float[Array, ""],
    Float[Array, ""],
    Float[Array, ""],
]


class FiveElementState(eqx.Module):
    """Scan carry of [`jaxcable.FiveElementModel`][] for one cable (all SI).

    The stress is split continuously into a loading part, the largest stress so far,
    and an unloading part, the drop below it; each drives its own family of
    Kelvin-Voigt elements (Boltzmann superposition with family-dependent kernels).
    No field depends on the sign of a force change.

    **Fields:**

    - `stress`: total stress sigma = F / A at the previous sample, Pa.
    - `sigma_L`: the largest stress so far, Pa (>= 0): the stress that drives the
        loading family.
    - `q_L2`, `q_L3`: strains of the loading Kelvin-Voigt elements (E_L2, eta_L2) and
        (E_L3, eta_L3) driven by `sigma_L`.
    - `q_UL2`, `q_UL3`: strains of the unloading elements (E_UL2, eta_UL2) and
        (E_UL3, eta_UL3) driven by sigma_UL = `stress` - `sigma_L` (<= 0: recovery).
    """

    stress: Float[Array, ""]
    sigma_L: Float[Array, ""]
    q_L2: Float[Array, ""]
    q_L3: Float[Array, ""]
    q_UL2: Float[Array, ""]
    q_UL3: Float[Array, ""]

    @property
    def sigma_UL(self) -> Float[Array, ""]:
        """The drop of the stress below its largest value so far, Pa (<= 0)."""
        return self.stress - self.sigma_L


def family_step(
    q2: Float[Array, ""],
    q3: Float[Array, ""],
    stresses: tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]],
    pieces: tuple[Float[Array, ""], Float[Array, ""]],
    E1: Float[Array, ""],
    E2: Float[Array, ""],
    eta2: Float[Array, ""],
    E3: Float[Array, ""],
    eta3: Float[Array, ""],
) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
    """Piao Eq. 1: a spring E1 in series with two Kelvin-Voigt elements (E2, eta2)
    and (E3, eta3), driven by one stress sigma. Under a step sigma applied at t = 0,

        eps(t) = sigma / E1 + sigma / E2 (1 - exp(-E2 t / eta2))
                            + sigma / E3 (1 - exp(-E3 t / eta3)),

    a transient creep element (retardation time eta2 / E2) and a long-term one
    (eta3 / E3). For any stress history each element obeys eta q' + E q = sigma(t);
    here the stress is linear over each of two pieces of the step (from `stresses[0]`
    to `stresses[1]` over `pieces[0]` s, then to `stresses[2]` over `pieces[1]` s)
    and each element takes its exact exponential update over both (no time-step
    error).

    **Arguments:**

    - `q2`, `q3`: the strains of the two elements at the start of the step.
    - `stresses`: the stress at the start, at the end of the first piece and at the
        end of the step, Pa.
    - `pieces`: the lengths of the two pieces, s.
    - `E1`, `E2`, `E3`: moduli, Pa; `eta2`, `eta3`: viscosities, Pa s.

    **Returns:**

    `(spring, q2, q3)`: the spring's strain and the two elements' strains at the end
    of the step, dimensionless.
    """
    start, kink, end = stresses
    h1, h2 = pieces

    def element(q, E, eta):
        q = kelvin_voigt_step(q, start, kink, h1, E, eta)
        return kelvin_voigt_step(q, kink, end, h2, E, eta)

    return end / E1, element(q2, E2, eta2), element(q3, E3, eta3)


def superposed_strain(
    loading: tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]],
    unloading: tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]],
) -> StrainParts:
    """Piao Eq. 2-3: unloading as the Boltzmann superposition of the load and an added
    stress -sigma_0 (a ramp while the payload is removed, then held), the added
    stress acting on the unloading family (the parameters with subscript UL). The
    strain is the sum of the two families' strains ([`family_step`][]): the loading
    family driven by the largest stress so far, the unloading family by the drop
    below it (<= 0), the unloading family's recovery bounded by what the loading
    family added.

    Eq. 2 prints eta_UL2 in the exponent of the E_UL3 term; the superposition gives
    eta_UL3 there, and that is what this sum computes. Eq. 3 (the strain after the
    unloading) is the same sum with the unloading stress held.

    **Recovery bound.** With added = spring_L + q_L2 + q_L3 (>= 0) and
    removed = -(spring_UL + q_UL2 + q_UL3) (>= 0), the three unloading terms are
    scaled by s = min(1, added / removed), so the strain is
    max(added - removed, 0): a cable recovers at most the elongation it was given
    and never ends shorter than new. With equal L and UL sets and a non-negative
    force, removed <= added (the linear solid's strain is >= 0) and the unscaled
    terms themselves are returned: the same operations as without the bound (the
    compiled program may round 1-2 ulp differently where XLA fuses it otherwise;
    measured in `docs/model_notes.md` point 10). With distinct sets the bound is
    active wherever the UL set would remove more than the L set added (a softer UL
    set after a long enough rest). s * removed = min(removed, added) is continuous,
    so the strain stays continuous in the force history.

    **Arguments:**

    - `loading`, `unloading`: `(spring, q2, q3)` of each family.

    **Returns:**

    The [`jaxcable.StrainParts`][]: both springs are `instantaneous`, the loading
    elements `creep`, the unloading elements the two recoveries.
    """
    spring_L, q_L2, q_L3 = loading
    spring_UL, q_UL2, q_UL3 = unloading
    unbounded = StrainParts(
        instantaneous=spring_L + spring_UL,
        creep=q_L2 + q_L3,
        recovery_short=-q_UL2,
        recovery_long=-q_UL3,
        apparatus=jnp.zeros_like(q_L2),
    )
    added = spring_L + unbounded.creep
    removed = unbounded.recovery_short + unbounded.recovery_long - spring_UL
    excess = removed > added
    # The guarded denominator keeps values and gradients finite where removed = 0
    # (excess is False there, and `share` unused).
    share = added / jnp.where(excess, removed, 1.0)
    # Where the bound is inactive, the unbounded parts themselves.
    return StrainParts(
        instantaneous=jnp.where(
            excess, spring_L + share * spring_UL, unbounded.instantaneous
        ),
        creep=unbounded.creep,
        recovery_short=jnp.where(
            excess, share * unbounded.recovery_short, unbounded.recovery_short
        ),
        recovery_long=jnp.where(
            excess, share * unbounded.recovery_long, unbounded.recovery_long
        ),
        apparatus=unbounded.apparatus,
    )


class AbstractFiveElement(AbstractCableModel[FiveElementState]):
    """Piao's five-element superposition ([`jaxcable.FiveElementModel`][]) with its
    loading and unloading parameter sets read at each step, so that one `advance`
    serves the model with fixed sets and one whose sets follow the sample
    (`jaxcable.LiveFiveElement`)."""

    @abc.abstractmethod
    def parameter_sets(
        self, force: Float[Array, ""], length: Float[Array, ""]
    ) -> tuple[ParameterSet, ParameterSet]:
        """The loading and the unloading set, each (E1, E2, eta2, E3, eta3) in Pa and
        Pa s, of a step ending at `force` (N) on a cable of free length `length` (m).
        """

    def flagged(self, loading: ParameterSet, parts: StrainParts) -> StrainParts:
        """The strain parts reported for a step whose loading set is `loading`:
        `parts` themselves by default."""
        del loading
        return parts

    def advance(
        self,
        state: FiveElementState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[FiveElementState, StrainParts]:
        # `direction` is not used: the split of the stress into its running maximum
        # and the drop below it is continuous in the force history (class docstring
        # of FiveElementModel).
        del direction
        loading_set, unloading_set = self.parameter_sets(force, cable.length)
        stress = force / cable.area
        sigma_L = running_max(state.sigma_L, stress)
        # The stress is linear over the step; its running maximum is constant until
        # the stress passes the previous maximum, at the share `split` of the step,
        # and follows it from there. Both families are advanced exactly over the two
        # pieces (the second has length 0 unless the step sets a new maximum).
        passes = stress > state.sigma_L
        rise = jnp.where(passes, stress - state.stress, 1.0)
        split = jnp.where(passes, (state.sigma_L - state.stress) / rise, 1.0)
        stress_split = jnp.where(passes, state.sigma_L, stress)
        pieces = (split * dt, (1.0 - split) * dt)
        loading = family_step(
            state.q_L2,
            state.q_L3,
            (state.sigma_L, state.sigma_L, sigma_L),
            pieces,
            *loading_set,
        )
        unloading = family_step(
            state.q_UL2,
            state.q_UL3,
            (
                state.stress - state.sigma_L,
                stress_split - state.sigma_L,
                stress - sigma_L,
            ),
            pieces,
            *unloading_set,
        )
        new_state = FiveElementState(
            stress=stress,
            sigma_L=sigma_L,
            q_L2=loading[1],
            q_L3=loading[2],
            q_UL2=unloading[1],
            q_UL3=unloading[2],
        )
        return new_state, self.flagged(
            loading_set, superposed_strain(loading, unloading)
        )


class FiveElementModel(AbstractFiveElement):
    r"""Piao et al.'s five-element creep model: a linear spring in series with two
    Kelvin-Voigt elements, with separate loading (L) and unloading (UL) parameters.

    **Equations (Piao Eq. 1-3).** Under a stress step sigma applied at t = 0
    (sigma = F / A, Pa) the strain is (Eq. 1)

        eps(t) = sigma / E_L1 + sigma / E_L2 (1 - exp(-E_L2 t / eta_L2))
                              + sigma / E_L3 (1 - exp(-E_L3 t / eta_L3)),

    i.e. an instantaneous spring, a transient creep element (retardation time
    tau_2 = eta_2 / E_2) and a long-term creep element (tau_3 = eta_3 / E_3). Eq. 2-3
    describe unloading as adding a stress -sigma_0 (a ramp from t_r to t_2, then held),
    with the unloading parameters: this is the Boltzmann superposition of the load step
    and the unloading ramp. Eq. 2 prints eta_UL2 in the exponent of the E_UL3 term;
    it is read as eta_UL3 (what the superposition gives).

    **Superposition reading, any force history.** The stress is split into a loading
    part, the largest stress so far, and an unloading part, the drop below it,

        sigma_L(t) = max_{s <= t} sigma(s),   sigma_UL(t) = sigma(t) - sigma_L(t) <= 0,

    (sigma_L + sigma_UL = sigma), and each drives its own family of elements with its
    own kernel:

        eps = sigma_L / E_L1 + q_L2 + q_L3 + sigma_UL / E_UL1 + q_UL2 + q_UL3,
        eta_k q_k' + E_k q_k = sigma_family(t)   (k = L2, L3 driven by sigma_L;
                                                   k = UL2, UL3 driven by sigma_UL).

    The force is linear between samples, so both parts are piecewise linear over a
    step (the running maximum has one kink, where the stress passes its previous
    maximum) and each element is advanced by its exact exponential update, split at
    that kink (no time-step error).

    **Where this is Eq. 1-3.** Eq. 1 holds exactly, for any L and UL sets, while the
    stress never falls below its largest value so far (the UL family is then idle).
    Eq. 2-3 as printed evaluate the *whole* history with the UL kernel,
    eps = sigma_0 (J_UL(t) - J_UL(t - t_r)) after an instant unloading
    (J(t) = 1/E_1 + sum_k (1 - exp(-E_k t / eta_k)) / E_k, the creep compliance).
    With equal L and UL sets this is the linear five-element (generalised Kelvin)
    solid and equals Eq. 1-3 exactly (Eq. 2 in its superposition reading, for any
    unloading ramp; Eq. 3 its instantaneous limit). With distinct sets it cannot be:
    the printed Eq. 1 ends at sigma_0 J_L(t_r) and Eq. 2 starts at sigma_0 J_UL(t_r),
    a jump at the reversal. Here the loading family keeps its L kernel, so after a
    load step sigma_0 (held to t_r, then any unloading to 0) the strain is

        eps(t) = max(Eq. 2-3 + D(t), 0),   D(t) = sigma_0 (J_L(t) - J_UL(t)),

    t counted from the load step: D(t_r) at the reversal, tending to the permanent
    set sigma_0 sum_k (1/E_Lk - 1/E_ULk), which is negative when the UL set is the
    more compliant (`docs/model_notes.md` point 10 gives measured numbers).

    **Recovery bound.** The unloading family removes at most what the loading family
    added (`superposed_strain`): its three terms are scaled by
    s = min(1, added / removed), so eps = max(added - removed, 0) >= 0 for any L and
    UL sets, and no history leaves the cable shorter than new. With equal sets and a
    non-negative force the bound never acts and the model is the linear solid as
    before, monotone in the load (adding a non-negative force to any history never
    shortens the cable later); a negative force (a slack cable's load-cell noise)
    no longer compresses it below its new length. The bound acts on the strain only,
    not on the states: while it is active the UL elements keep their excess
    recovery, which a later reloading takes back first (a cable reloaded after a
    bounded rest lengthens later than a new one; measured in `docs/model_notes.md`
    point 10). Capping the states instead would lose the continuity bound below.

    **Cycles below the previous maximum.** A reloading that stays below the largest
    stress so far raises sigma_UL back towards 0: it takes the recovery back with the
    UL kernel instead of adding more stress to the loading family, and only a stress
    above the previous maximum loads the L family again. This is the choice that keeps
    the strain continuous in the force history. The earlier reading (each step's
    increment to the family of its branch, the sign of the force change) made sigma_L
    the sum of all upward increments: under a measured force every noise blip is a
    reversal, so sigma_L grew with the total variation of the noise and the strain
    drifted (12 mm per N of noise on a 300 mm cable, measured by
    `benchmarks/continuity.py`). Here
    a perturbation d of every force sample moves sigma_L by at most d / A and
    sigma_UL by at most 2 d / A, so the strain moves by at most

        (d / A) (1/E_L1 + 1/E_L2 + 1/E_L3 + 2 (1/E_UL1 + 1/E_UL2 + 1/E_UL3)),

    however long or noisy the history (the recovery bound, max(added - removed, 0),
    moves by no more than added and removed do). `direction` is not used.

    **Strain parts.** `instantaneous` = sigma_L / E_L1 + s sigma_UL / E_UL1 (both
    springs), `creep` = q_L2 + q_L3, `recovery_short` = -s q_UL2, `recovery_long` =
    -s q_UL3, with s the recovery bound's share (1 unless the bound is active).

    **Default parameters.** Loading: Piao Table 1 (`jaxcable.PIAO_TABLE1`),
    E_L2 = 9.5e9 Pa, E_L3 = 5.0e10 Pa, eta_L2 = 1.0e10 Pa s (tau_2 ~ 1.05 s),
    eta_L3 = 1.0e13 Pa s (tau_3 = 200 s). E_L1 is a function of payload and cable
    length in the paper (Table 3); the default 2.2e14 Pa is the Table 3 surface at
    the robot's maximum payload 65 kg on a 7.4 m cable, read as described in
    [`jaxcable.PIAO_TABLE3`][]: Table 3's parameter and unit did not survive, and
    this value, about 2000 times the UHMWPE fibre modulus, is not a measured spring.
    It makes the spring practically rigid (strain < 1e-6 at the paper's loads): the
    elongation is carried by the two Kelvin-Voigt elements. The unloading table
    (Table 2) is lost, so **the unloading parameters default to the loading ones**
    (E_UL1 = E_L1, E_UL2 = E_L2, ...): the default model is the linear five-element
    solid, which recovers fully after unloading.
    Fit the UL set to recovery data to obtain the paper's loading/unloading asymmetry.

    **Fields (SI):**

    - `E_L1`, `E_L2`, `E_L3`: loading spring, transient and long-term moduli, Pa.
    - `eta_L2`, `eta_L3`: loading transient and long-term viscosities, Pa s.
    - `E_UL1`, `E_UL2`, `E_UL3`: unloading moduli, Pa.
    - `eta_UL2`, `eta_UL3`: unloading viscosities, Pa s.

    All fields are arrays; give them a leading batch axis and `jax.vmap` over the model
    to simulate parameter sets.
    """

    CLI_NAME = "five-element"

    E_L1: Float[Array, "*batch"] = parameter(2.2e14, **MODULUS)
    E_L2: Float[Array, "*batch"] = table1_field("E_L2")
    E_L3: Float[Array, "*batch"] = table1_field("E_L3")
    eta_L2: Float[Array, "*batch"] = table1_field("eta_L2")
    eta_L3: Float[Array, "*batch"] = table1_field("eta_L3")
    E_UL1: Float[Array, "*batch"] = parameter(2.2e14, **MODULUS)
    E_UL2: Float[Array, "*batch"] = table1_field("E_UL2")
    E_UL3: Float[Array, "*batch"] = table1_field("E_UL3")
    eta_UL2: Float[Array, "*batch"] = table1_field("eta_UL2")
    eta_UL3: Float[Array, "*batch"] = table1_field("eta_UL3")

    # `check` (derived from the declarations): every modulus and viscosity finite
    # and > 0. Any pair of L and UL sets is admissible: the recovery bound keeps the
    # strain >= 0 whatever their relation, so distinct sets need no flag.

    @classmethod
    def from_sets(
        cls, loading: ParameterSet, unloading: ParameterSet
    ) -> "FiveElementModel":
        """The model of a loading and an unloading set, each (E1, E2, eta2, E3,
        eta3) in Pa and Pa s."""
        return cls(*(s[i] for s in (loading, unloading) for i in (0, 1, 3, 2, 4)))

    def parameter_sets(
        self, force: Float[Array, ""], length: Float[Array, ""]
    ) -> tuple[ParameterSet, ParameterSet]:
        del force, length
        return (
            (self.E_L1, self.E_L2, self.eta_L2, self.E_L3, self.eta_L3),
            (self.E_UL1, self.E_UL2, self.eta_UL2, self.E_UL3, self.eta_UL3),
        )

    def init(self, cable: Cable) -> FiveElementState:
        zero = state_zero(cable, self.E_L1)
        return FiveElementState(
            stress=zero, sigma_L=zero, q_L2=zero, q_L3=zero, q_UL2=zero, q_UL3=zero
        )
