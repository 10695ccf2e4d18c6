"""A simulated Open Protocol controller (a real server on loopback or a pty): the controller
(``controller.py``), its results and curves, the server, and the command that runs it as a
process (``python -m drivers.wrench.sim``, ``cli.py``).

Why a package apart from the protocol (:mod:`drivers.wrench.openprotocol`): the simulator
plays the controller's side of the link and is used by tests, demos and benchmarks; the
station's driver never imports it."""
