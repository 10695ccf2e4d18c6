"""``stationd demo``: the station (:mod:`stationd.demo.station`) and the vision
(:mod:`stationd.demo.vision`) run on the simulator.  A demo drives the runtime from above: it
imports the simulator, and nothing of the runtime imports it."""
