"""The station's shell: everything that meets the world for the pure core
(:mod:`stationd.station`): the serve loop (``stationd run``), the daemon's loops and timing,
the devices opened and kept, the records written, the journal and sd_notify.

Why a package of its own: the core decides, the shell carries out and feeds back what it saw;
a reader finds each side in its folder, and the layers contract holds them apart."""
