"""The station: the pure core (the rules, its inputs and actions, bolt matching, the NOK
policy, the pairs trusted); no I/O: the shell (:mod:`stationd.shell`) feeds and carries it out."""
