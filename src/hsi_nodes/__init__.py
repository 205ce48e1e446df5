"""Messages, transport, nodes, launcher, recorder and the ``hsi`` command line."""

__version__ = "0.1.0"
