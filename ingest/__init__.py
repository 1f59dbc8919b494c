"""The edge: wire format, zenoh publish/subscribe, MCAP archive, replay, scene simulator."""
