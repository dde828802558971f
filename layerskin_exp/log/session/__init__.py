"""The session format: what a trial file holds and how (schema: topics, Foxglove schemas,
payload layouts), written crash-safely (writer) and read back as aligned numpy arrays (reader)."""
