"""Open Protocol, the integrator's side: messages and framing (``message.py``), the results,
identities and curves read from them, the link-level rules, and the driver
(``client.py``: :class:`~drivers.wrench.openprotocol.client.OpenProtocolWrench`, a facade over
the subjects of a session, each a module of its own: the channel, the session's start, the
supervisor thread, results, old results, curves, commands; ``client.py`` lists them).

Why a package: the protocol is the largest part of the wrench drivers and has layers of its
own (framing, reading, the client's session) that the register-driven controllers share
nothing of."""
