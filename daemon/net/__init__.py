"""ZeroMQ: the publisher and request server, the subscriber client, CURVE keys."""
