"""The one error class of :mod:`endeff_ros.bag`."""

from __future__ import annotations

from endeff_ros.core.errors import EndeffError


class BagError(EndeffError):
    """A bag cannot be used: missing topic, unknown encoding, truncated or corrupt file...

    The message always names the bag and the problem; ``bag`` holds the path as given.
    """

    def __init__(self, bag: object, problem: str) -> None:
        self.bag = str(bag)
        self.problem = problem
        super().__init__(f'{self.bag}: {problem}')

    def __reduce__(self) -> tuple[type[BagError], tuple[str, str]]:
        """Pickle by (bag, problem) so the error crosses process boundaries intact."""
        return (type(self), (self.bag, self.problem))
