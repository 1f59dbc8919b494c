"""The OPC UA server: millwatch's values and alarms for control rooms' DCS/SCADA (asyncua).

What is here, and how data flows (backend → values → address space; board → conditions;
methods → backend's operator actions → board → conditions):

* :mod:`millwatch.opcua.server` — :class:`~millwatch.opcua.server.OpcUaServer`: asyncua in its own
  thread over a :class:`~millwatch.api.backend.Backend` (the REST API's: the runtime in process
  under ``millwatch serve``/the demo, the workers over zenoh under ``millwatch api``); polls it
  every ``[opcua] update_s`` and follows the alarm board; BuildInfo names millwatch.
* :mod:`millwatch.opcua.values` — pure: the backend's answers of a mill as named points (the node
  layout table), each with its sample time and EURange.
* :mod:`millwatch.opcua.address_space` — ``Objects/Millwatch/<site>/<mill>/…`` (mills of type
  ``MillType``; Millwatch, sites and mills event notifiers): nodes made from the points
  (AnalogItemType where a range is known), only changed values written, with SourceTimestamp
  and ServerTimestamp.
* :mod:`millwatch.opcua.conditions` — alarms as Part 9 condition objects
  (ExclusiveLevelAlarmType/AlarmConditionType with ShelvingState, ConfirmedState, InputNode)
  and their events; ConditionRefresh(2) for any notifier.
* :mod:`millwatch.opcua.blueprint` — a condition after the first of its type made by copying
  the first one's nodes (asyncua's instantiate browses the type for every node).
* :mod:`millwatch.opcua.methods` — the operator methods (Acknowledge, Confirm, AddComment,
  TimedShelve/OneShotShelve/Unshelve, Enable/Disable) through the backend's ``act`` (what the
  REST actions call), as the OPC UA user; operators only.
* :mod:`millwatch.opcua.history` — HistoryRead: alarm events from the store's transitions;
  values ``BadHistoryOperationUnsupported``.
* :mod:`millwatch.opcua.access` — logins (user/password, user certificates, anonymous read-only
  plus ConditionRefresh) and the per-request access rule.
* :mod:`millwatch.opcua.trust` — the trust list of client application certificates
  (``[opcua] trusted_clients_dir``; the refused saved in ``rejected/``).
* :mod:`millwatch.opcua.certificate` — the self-signed server certificate made at first start.
* :mod:`millwatch.opcua.units` — UNECE engineering units (``EUInformation``).
* :mod:`millwatch.opcua.ua_types` — typed constructors of asyncua's NodeId, StatusCode and
  DataValue.
* :mod:`millwatch.opcua.launch` — :func:`~millwatch.opcua.launch.start_opcua`, what ``serve``,
  ``api`` and the demo call (asyncua is imported only when ``[opcua] enabled``).

Where things go: a new value is a point in :mod:`~millwatch.opcua.values` (its node appears by
itself; its EURange in :func:`~millwatch.opcua.values.eu_range`); a new alarm field a line of
``_fill`` in :mod:`~millwatch.opcua.conditions`; a new operator method a line of ``_METHODS`` in
:mod:`~millwatch.opcua.methods`. The commands import this package only when ``[opcua] enabled``
(asyncua is not loaded otherwise).
"""
