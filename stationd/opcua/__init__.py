"""The station's OPC UA server in the joining-system companion model (OPC 40450-1 IJT Base
1.01): :class:`stationd.opcua.server.OpcUaServer`, configured by the station file's ``opcua:``
section (:class:`OpcUaConfig`).  asyncua (pinned) is used in this package only, and imported
only by ``stationd.opcua.server`` and ``.model``: reading a station file does not load it."""

from stationd.opcua.config import OpcUaConfig

__all__ = ["OpcUaConfig"]
