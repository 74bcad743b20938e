"""Names of the error states and where each sits in the state vector.

The filter, the alignment, the real-time prediction and every aiding source address the error
state through a :class:`StateLayout`, never through bare indices, so that a layout with more
states (say, gyro Gauss-Markov drift states appended as ``("gyro_drift", 3)``) changes no code
that does not use the new states.
"""

from collections.abc import Iterable

# Components of a three-axis block: ENU for attitude, velocity and position errors, body x, y, z
# for the IMU biases.
EAST, NORTH, UP = 0, 1, 2
X, Y, Z = 0, 1, 2

_RESERVED_NAMES = frozenset(("dim", "names", "slice_of", "indices", "index"))


class StateLayout:
    """Blocks of the error state, in order: ``StateLayout(("attitude", 3), ("velocity", 3))``.

    ``layout.attitude`` (or ``layout.slice_of("attitude")``) is the block's slice of the state
    vector and of the covariance's rows and columns; ``layout.index("attitude", UP)`` the index
    of one component; ``layout.indices("velocity")`` every index of a block; ``layout.dim`` the
    number of states.
    """

    def __init__(self, *blocks: tuple[str, int]):
        slices: dict[str, slice] = {}
        start = 0
        for name, size in blocks:
            if not name.isidentifier() or name.startswith("_") or name in _RESERVED_NAMES:
                raise ValueError(f"'{name}' cannot name a state block")
            if name in slices:
                raise ValueError(f"state block '{name}' is given twice")
            if size < 1:
                raise ValueError(f"state block '{name}' must have at least one state")
            slices[name] = slice(start, start + size)
            start += size
        self._slices = slices
        self.dim = start
        self.names = tuple(slices)
        # Plain attributes: the blocks are read in the filter's inner loops.
        for name, block in slices.items():
            setattr(self, name, block)

    def slice_of(self, name: str) -> slice:
        """The slice of block ``name`` (KeyError naming it when the layout has no such block)."""
        return self._slices[name]

    def indices(self, name: str) -> range:
        """Every index of block ``name``."""
        block = self._slices[name]
        return range(block.start, block.stop)

    def index(self, name: str, component: int) -> int:
        """Index of component ``component`` (0-based, e.g. :data:`UP`) of block ``name``."""
        block = self._slices[name]
        if not 0 <= component < block.stop - block.start:
            raise IndexError(f"state block '{name}' has no component {component}")
        return block.start + component

    def __contains__(self, name: str) -> bool:
        return name in self._slices

    def __repr__(self) -> str:
        blocks: Iterable[str] = (
            f"({name!r}, {block.stop - block.start})" for name, block in self._slices.items()
        )
        return f"StateLayout({', '.join(blocks)})"
