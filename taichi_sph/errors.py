"""Exceptions with the exit codes the CLI maps them to.

- InputError (exit 2): bad config, file or command line; raised before anything is written.
- InstabilityError: a run that went numerically wrong; frames written so far are kept. Its exit code
  tells the cause family (the stability guard, taichi_sph/guard.py, names the cause):

  | exit | family      | causes                                                              |
  |------|-------------|---------------------------------------------------------------------|
  | 3    | `bounds`    | speed or density ratio beyond its bound, neighbour-list overflow   |
  | 4    | `nonfinite` | NaN or Inf in position, velocity, pressure or density               |
  | 5    | `solver`    | pressure solver (CG) diverged or did not converge, time step collapsed |
  | 6    | `domain`    | particles left the domain (guard.out_of_domain: error), a wall particle moved |
"""

EXIT_INPUT = 2
EXIT_UNSTABLE = 3
#: exit code of each family of instability causes
EXIT_BY_FAMILY = {"bounds": 3, "nonfinite": 4, "solver": 5, "domain": 6}


class InputError(ValueError):
    """Bad user input. The message is one line that names the key or file."""

    exit_code = EXIT_INPUT


class InstabilityError(RuntimeError):
    """The simulation left its valid range; message names step, time, quantity and particles."""

    def __init__(self, message: str, *, step: int = -1, time: float = float("nan"), quantity: str = "",
                 particles=(), family: str = "bounds"):
        super().__init__(message)
        self.step = step
        self.time = time
        self.quantity = quantity
        self.particles = [int(i) for i in particles]
        if family not in EXIT_BY_FAMILY:
            raise ValueError(f"unknown instability family {family!r}")
        self.family = family

    @property
    def exit_code(self) -> int:
        return EXIT_BY_FAMILY[self.family]
