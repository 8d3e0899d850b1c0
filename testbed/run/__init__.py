"""One run of the testbed, wired: scenario schema, link codecs, nodes, runner, real-time runs,
recorder and metrics. The only place that joins operator, link and vehicle."""
