"""The OPC UA server: millwatch's values and alarms for control rooms' DCS/SCADA (asyncua).

What is here, and how data flows (backend → values → address space; board → conditions):

* :mod:`service.opcua.server` — :class:`~service.opcua.server.OpcUaServer`: asyncua in its own
  thread over a :class:`~service.api.backend.Backend` (the REST API's: the runtime in process
  under ``millwatch serve``/the demo, the workers over zenoh under ``millwatch api``); polls it
  every ``[opcua] update_s`` and follows the alarm board.
* :mod:`service.opcua.values` — pure: the backend's answers of a mill as named points (the node
  layout table).
* :mod:`service.opcua.address_space` — ``Objects/Millwatch/<site>/<mill>/…``: nodes made from
  the points, only changed values written.
* :mod:`service.opcua.conditions` — alarms as Alarms & Conditions events; Acknowledge through
  the backend's ``ack`` (what ``POST /alarms/{id}/ack`` calls).
* :mod:`service.opcua.access` — logins (user/password, user certificates, anonymous read-only)
  and the per-request access rule.
* :mod:`service.opcua.certificate` — the self-signed server certificate made at first start.
* :mod:`service.opcua.units` — UNECE engineering units (``EUInformation``).
* :mod:`service.opcua.ua_types` — typed constructors of asyncua's NodeId and StatusCode.
* :mod:`service.opcua.launch` — :func:`~service.opcua.launch.start_opcua`, what ``serve``,
  ``api`` and the demo call (asyncua is imported only when ``[opcua] enabled``).

Where things go: a new value is a point in :mod:`~service.opcua.values` (its node appears by
itself); a new alarm field a line of ``_fill`` in :mod:`~service.opcua.conditions`. The commands
import this package only when ``[opcua] enabled`` (asyncua is not loaded otherwise).
"""
