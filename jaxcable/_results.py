import optimistix as optx


# An equinox Enumeration extends another by subclassing; pyright takes it for an
# Enum, whose subclasses are refused.
class RESULTS(optx.RESULTS):  # pyright: ignore[reportGeneralTypeIssues]
    """Outcome of a simulation or a fit; each member's value is its error message.

    The members of optimistix's `RESULTS` are members here too (a fit reports its
    solver's result, [`jaxcable.FitResult`][]`.result`); `RESULTS.promote` converts
    one of optimistix's results.

    A simulation run with `throw=True` (the default) raises with this message when the
    result is not `RESULTS.successful`; with `throw=False` the result is returned in
    [`jaxcable.Trajectory`][]`.result`, one per cable when vmapped, so that a
    Monte-Carlo batch keeps the cables that succeeded.

    Each sample is checked in order: its own cause first (a solve that failed, a time
    or force that is not physical, a strain that is not finite or, for a solved
    sample, above the model's limit), then `strain_beyond_break`, a strain above the
    cable's breaking strain ([`jaxcable.Cable`][]`.breaking_strain`); the first
    failing sample's result is the simulation's.
    """

    successful = ""
    newton_failed = (
        "The Newton solve for a sample's unknown (the loading time of a rate-driven "
        "test, or the force of an elongation-driven test) did not converge, although "
        "the residual does not rule a solution out: a numerical failure. Try a "
        "solver with more steps (`solver=jaxcable.Newton(tol, max_steps=...)`) or "
        "finer samples."
    )
    unreachable_force = (
        "A force sample of the rate-driven test cannot be reached at this crosshead "
        "speed (Park Eq. 6 has no solution at dt >= 0): on a loading ramp the cable "
        "creeps at least as fast as the crosshead strains it (for Park's model when "
        "its flow (sigma_a / eta0) sinh(F / (A sigma_a)) >= v / L0), so the force is "
        "never reached; on an unloading "
        "ramp the model's strain at the lower force is already above the crosshead's. "
        "This is the physics of the model and parameters, not a solver failure: "
        "raise the speed, lower the force, or check the parameters."
    )
    nonphysical_time = (
        "A solved loading time was negative or non-finite (Park Eq. 5-6): the force "
        "protocol cannot be reached at this crosshead speed."
    )
    nonphysical_force = (
        "A solved force was negative or non-finite, or a force reached the cable's "
        "stiffness scale E1c*A where the hardening law (Park Eq. 1) no longer applies."
    )
    nonphysical_strain = (
        "The strain became non-finite (inf or NaN), or a sample's time or force was "
        "solved by the integrated model at a strain above 1 (the cable at twice its "
        "length, beyond the "
        "breaking strain of any polymer cable and the range where the hardening "
        "law, Park Eq. 2, lets the strain determine the force): check the "
        "parameters' units and size."
    )
    parameter_out_of_domain = (
        "A model parameter is outside its domain: e.g. the long-term retardation time "
        "t_r2 = lambda1 / strain_rate**2 - lambda2 (Park Eq. 8) is not positive for "
        "this cable's strain rate, or a modulus, viscosity or time constant is not "
        "positive."
    )
    strain_beyond_break = (
        "The strain exceeded the cable's breaking strain (`Cable.breaking_strain`): "
        "the cable would have broken, and the model's elongations beyond it describe "
        "no real cable. Lower the force or the time under load, or give the cable "
        "its measured breaking strain (`math.inf` for a material that does not "
        "break, such as an elastomer)."
    )
    every_start_failed = (
        "Every start of the fit failed: the residuals were not finite at any start "
        "(a simulation failed, or a parameter left its domain). Try other start "
        "values or fewer fitted parameters."
    )
    estimator_diverged = (
        "The online estimator of the cables' parameters diverged: its prediction was "
        "not finite, its model failed on the measured forces, or the position fixes "
        "disagreed with it beyond its gate for several fixes in a row (a force of the "
        "wrong sign, a miscalibrated load cell, a model that cannot describe the "
        "cables). Its estimates are frozen and the predicted elongation is the "
        "nominal model's."
    )
    signal_lost = (
        "A signal the online estimator needs is missing: no position fix for longer "
        "than its `max_fix_gap`, or a load cell whose reading has not changed for "
        "longer than its `stuck_time`. The estimator predicts without updating its "
        "estimates until the signal is back."
    )
