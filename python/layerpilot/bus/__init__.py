"""The Zenoh bus: session configuration, key names, protobuf message codecs, rejection of bad input."""
