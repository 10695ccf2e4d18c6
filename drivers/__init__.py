"""Device drivers: cameras, the lift PLC and the tightening controller.

One interface per device kind (``drivers/<kind>/base.py``), real backends and a simulated twin
beside them, chosen by URL in the station config.  The backends arrive with the drivers issue;
the vision code never imports from here.
"""
