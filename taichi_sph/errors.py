"""Exceptions with the exit codes the CLI maps them to.

- InputError (exit 2): bad config, file or command line; raised before anything is written.
- InstabilityError (exit 3): a run that went numerically wrong; frames written so far are kept.
"""

EXIT_INPUT = 2
EXIT_UNSTABLE = 3


class InputError(ValueError):
    """Bad user input. The message is one line that names the key or file."""

    exit_code = EXIT_INPUT


class InstabilityError(RuntimeError):
    """The simulation left its valid range; message names step, time, quantity and particles."""

    exit_code = EXIT_UNSTABLE

    def __init__(self, message: str, *, step: int = -1, time: float = float("nan"), quantity: str = "",
                 particles=()):
        super().__init__(message)
        self.step = step
        self.time = time
        self.quantity = quantity
        self.particles = list(particles)
