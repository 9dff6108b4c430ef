import equinox as eqx


class RESULTS(eqx.Enumeration):
    """Outcome of a simulation; each member's value is its error message.

    A simulation run with `throw=True` (the default) raises with this message when the
    result is not `RESULTS.successful`; with `throw=False` the result is returned in
    [`jaxcable.Trajectory`][]`.result`, one per cable when vmapped, so that a
    Monte-Carlo batch keeps the cables that succeeded.
    """

    successful = ""
    newton_failed = (
        "The Newton solve for a sample's unknown (the loading time of a rate-driven "
        "test, or the force of an elongation-driven test) did not converge. The cable "
        "may be unable to follow the protocol: e.g. its creep rate exceeds the "
        "crosshead strain rate, so the force limit is never reached."
    )
    nonphysical_time = (
        "A solved loading time was negative or non-finite (Park Eq. 5-6): the force "
        "protocol cannot be reached at this crosshead speed."
    )
    nonphysical_force = (
        "A solved force was negative or non-finite, or a force reached the cable's "
        "stiffness scale E1c*A where the hardening law (Park Eq. 1) no longer applies."
    )
    nonphysical_strain = "The strain became non-finite (inf or NaN)."
    parameter_out_of_domain = (
        "A model parameter is outside its domain: e.g. the long-term retardation time "
        "t_r2 = lambda1 / strain_rate**2 - lambda2 (Park Eq. 8) is not positive for "
        "this cable's strain rate, or a modulus, viscosity or time constant is not "
        "positive."
    )
