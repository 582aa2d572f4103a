"""The package version, in a module of its own so that any module can import it without
importing the package ``__init__`` (no import cycles)."""

__version__ = "0.5.0.dev0"  # the next release; stores compare results_version, not this

#: The version of the *results*: it changes only when the same parameter record (family, integrator
#: and its settings, grid, seed, ...) would give different numbers, and it is what a resumed store is
#: compared on (with the parameters), so a new granchain that computes the same numbers resumes and
#: extends the stores of the old one. 1: granchain 0.1.0 to 0.4.x and this version (the paper's
#: family gives bitwise the stores 0.1.0 wrote; tests/test_families.py).
RESULTS_VERSION = 1

#: Results version of the stores written by each earlier granchain (their records name the package
#: version instead). A version not listed here is refused on resume, never guessed.
RESULTS_OF_VERSION = {"0.1.0": 1, "0.2.0": 1, "0.3.0": 1, "0.4.0": 1}
