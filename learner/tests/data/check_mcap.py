"""Reads an MCAP file of `learner dataset export --format mcap` / `learner serve --mcap` with the
`mcap` Python reader (pip install mcap; not part of `cargo test`): every channel and message,
counted per topic, each message decoded as JSON and checked against its schema's fields.

    python learner/tests/data/check_mcap.py RUN.mcap [EPISODES]

With EPISODES (the number of recorded episodes) it also checks the per-step and per-episode
counts (every episode of the same length).
"""
import json
import sys
from collections import Counter

from mcap.reader import make_reader


def main(path, episodes=None):
    counts = Counter()
    last = -1
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert channel.message_encoding == "json", channel
            assert schema.encoding == "jsonschema", schema
            props = json.loads(schema.data)["properties"]
            msg = json.loads(message.data)
            missing = set(props) - set(msg)
            assert not missing, (channel.topic, missing)
            assert message.log_time >= last, (channel.topic, message.log_time)
            last = message.log_time
            counts[channel.topic] += 1
    print(f"{path}: {len(channels)} channels, {sum(counts.values())} messages, "
          f"last log time {last / 1e9:.1f} s")
    for topic in sorted(channels):
        c = channels[topic]
        print(f"  {topic:14s} {summary.schemas[c.schema_id].name:24s} {counts[topic]}")
    if episodes is not None:
        steps = counts["/state"] // episodes
        assert counts["/episode"] == episodes, counts
        for topic in ("/joint_states", "/state", "/action"):
            assert counts[topic] == episodes * steps, (topic, counts)
        print(f"  {episodes} episodes of {steps} steps: counts consistent")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else None)
