"""MCAP files (the ROS 2 bag format, and others) through the `mcap` package.

A column is a topic and a field path in its messages, written `TOPIC:FIELD`, e.g.
`/joint1/state:position` or `/joint_states:effort[0]` (list elements by index, nested fields
with dots: `/imu:angular_velocity.z`); `TOPIC:log_time` is the message's log time in seconds.
A field path that only one topic has is also available without the topic (a logger that
publishes `t, theta_m, theta_l, current, torque` on one topic needs no column map). Messages
in JSON are decoded directly, ROS 2 (CDR) messages with `mcap-ros2-support`.

Every column of a recording must come from topics published together (the same number of
messages): hdjax does not resample, since interpolating a torque or a current is a modelling
choice that belongs before the log is read.
"""

from __future__ import annotations

import contextlib
import json
import struct
from pathlib import Path

import numpy as np

from .._errors import DataError
from ._columns import require


def _flatten(obj, prefix: str, out: dict) -> None:
    if isinstance(obj, bool):
        out[prefix] = float(obj)
    elif isinstance(obj, int | float):
        out[prefix] = float(obj)
    elif isinstance(obj, dict):
        for k, v in obj.items():
            _flatten(v, f"{prefix}.{k}" if prefix else str(k), out)
    elif isinstance(obj, list | tuple | np.ndarray):
        for i, v in enumerate(obj):
            _flatten(v, f"{prefix}[{i}]", out)
    elif hasattr(obj, "__slots__"):  # ROS 2 messages decoded by mcap_ros2
        for k in obj.__slots__:
            _flatten(getattr(obj, k), f"{prefix}.{k}" if prefix else k, out)


def _decoder(path: Path, schema, channel):
    enc = channel.message_encoding
    if enc == "json":
        return lambda data: json.loads(data)
    if enc == "cdr":
        require("mcap_ros2", "mcap")
        from mcap_ros2.decoder import DecoderFactory

        dec = DecoderFactory().decoder_for(enc, schema)
        if dec is not None:
            return dec
    raise DataError(
        f"{path}: topic {channel.topic!r} uses message encoding {enc!r}; hdjax reads json and "
        "ROS 2 cdr messages"
    )


def _messages(path: Path, topics=None):
    """(topic, log_time [s], flat field dict) of every message, in log-time order."""
    require("mcap", "mcap")
    from mcap.reader import make_reader

    decoders = {}
    with _readable(path), path.open("rb") as fh:
        reader = make_reader(fh)
        for schema, channel, message in reader.iter_messages(topics=topics):
            dec = decoders.get(channel.id)
            if dec is None:
                dec = decoders[channel.id] = _decoder(path, schema, channel)
            flat: dict = {}
            _flatten(dec(message.data), "", flat)
            yield channel.topic, message.log_time * 1e-9, flat


@contextlib.contextmanager
def _readable(path: Path):
    """Turn what the `mcap` reader raises on a damaged file (truncated, not MCAP at all) into
    one line; every read of the file goes through here."""
    from mcap.exceptions import McapError

    try:
        yield
    except DataError:  # already one line (a message encoding hdjax does not read)
        raise
    except (McapError, json.JSONDecodeError, EOFError, ValueError, struct.error) as err:
        raise DataError(
            f"{path}: not a readable MCAP file ({' '.join(str(err).split())})"
        ) from None


def _catalogue(path: Path) -> tuple[list[str], dict[str, tuple[str, str]]]:
    """Column names and, for each, its (topic, field); from each topic's first message."""
    seen: dict[str, list[str]] = {}
    require("mcap", "mcap")
    from mcap.reader import make_reader

    with _readable(path), path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    all_topics = {c.topic for c in summary.channels.values()} if summary else None
    for topic, _, flat in _messages(path):
        if topic not in seen:
            seen[topic] = list(flat)
        if all_topics is not None and set(seen) >= all_topics:
            break
    if not seen:
        raise DataError(f"{path}: the MCAP file holds no messages")
    where: dict[str, tuple[str, str]] = {}
    owners: dict[str, list[str]] = {}
    for topic, fields in seen.items():
        where[f"{topic}:log_time"] = (topic, "log_time")
        for f in fields:
            where[f"{topic}:{f}"] = (topic, f)
            owners.setdefault(f, []).append(topic)
    for f, ts in owners.items():
        if len(ts) == 1 and f not in where:
            where[f] = (ts[0], f)
    return list(where), where


def column_names(path) -> list[str]:
    return _catalogue(Path(path))[0]


def default_columns(path, used: list[str]) -> list[str]:
    """The mapped columns plus every other field of their topics (without the topic prefix
    when unique), i.e. the extras kept when a map does not list them."""
    names, where = _catalogue(Path(path))
    topics = {where[n][0] for n in used if n in where}
    if not topics:  # nothing mapped yet: the topics that carry bare field names
        topics = {where[n][0] for n in names if ":" not in n}
    taken = {where[n] for n in used if n in where}
    out = list(used)
    for n in names:
        topic, field = where[n]
        if topic in topics and (topic, field) not in taken and field != "log_time":
            if ":" not in n or n.partition(":")[2] not in names:
                out.append(n)
                taken.add((topic, field))
    return out


def iter_tables(path, chunk: int, names=None):
    """Tables of at most `chunk` messages per topic, topics kept in step."""
    path = Path(path)
    _, where = _catalogue(path)
    names = default_columns(path, []) if names is None else names
    topics = sorted({where[n][0] for n in names})
    buf = {t: [] for t in topics}
    counts = dict.fromkeys(topics, 0)

    def take(k: int) -> dict[str, np.ndarray]:
        out = {}
        for n in names:
            topic, field = where[n]
            rows = buf[topic][:k]
            key = "__log_time__" if field == "log_time" else field
            try:
                out[n] = np.array([r[key] for r in rows], dtype=np.float64)
            except KeyError:
                raise DataError(
                    f"{path}: a message on {topic!r} lacks the field {field!r} that its first "
                    "message has; every message of a topic must have the same fields"
                ) from None
        for t in topics:
            del buf[t][:k]
        return out

    for topic, log_time, flat in _messages(path, topics):
        flat["__log_time__"] = log_time
        buf[topic].append(flat)
        counts[topic] += 1
        if min(len(b) for b in buf.values()) >= chunk:
            yield take(chunk)
    if len(set(counts.values())) > 1:
        detail = ", ".join(f"{t} ({n} messages)" for t, n in counts.items())
        raise DataError(
            f"{path}: the columns come from topics with different message counts: {detail}; "
            "columns of one recording must be published together (resample the log first)"
        )
    rest = min(len(b) for b in buf.values())
    if rest:
        yield take(rest)


def read_table(path, names=None) -> dict[str, np.ndarray]:
    parts = list(iter_tables(path, 1 << 62, names))
    if not parts:
        raise DataError(f"{path}: no messages on the topics of the requested columns")
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
