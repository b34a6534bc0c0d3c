#!/usr/bin/env python3
"""Checks MCAP files against the specification (https://mcap.dev/spec), independently of idms's
C++ reader: Python standard library only, written from the specification.

Checked: the magic at both ends; Header first and Footer last; the framing of every record; what
may appear in the data section, in chunks and in the summary; Schema before Channel before Message;
duplicate Schema/Channel records identical; each chunk's times, sizes and CRC, its records and its
Message Index records (exactly one per channel with messages, every entry pointing at a Message of
that channel and log time); Data End last in the data section with the CRC of every byte before it;
summary groups contiguous, Chunk Index / Metadata Index records matching what they index, Statistics
matching the file; Summary Offset records matching the groups; the Footer's offsets and summary CRC.
zstd is not in the standard library: a zstd chunk's records are not decompressed, so its contents
are checked only through its message indexes. Write files with compression off for a full check.

Usage: mcap_check.py FILE... (prints one line per file; exits 1 on the first problem)
       mcap_check.py --self-test FILE (an uncompressed file: damaged copies must be rejected)
"""
import struct
import sys
import zlib

MAGIC = b"\x89MCAP0\r\n"
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = range(1, 9)
ATTACHMENT, ATTACHMENT_INDEX, STATISTICS, METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END = range(9, 16)
DATA_OPS = {SCHEMA, CHANNEL, MESSAGE, ATTACHMENT, CHUNK, MESSAGE_INDEX, METADATA, DATA_END}
SUMMARY_OPS = {SCHEMA, CHANNEL, CHUNK_INDEX, ATTACHMENT_INDEX, STATISTICS, METADATA_INDEX}
CHUNK_OPS = {SCHEMA, CHANNEL, MESSAGE}


class Bad(Exception):
    def __init__(self, offset, what):
        super().__init__(f"byte {offset}: {what}")


class Fields:
    """Little-endian fields of one record's content, bounds-checked."""

    def __init__(self, data, offset):
        self.data, self.pos, self.base = data, 0, offset

    def take(self, n, what):
        if n > len(self.data) - self.pos:
            raise Bad(self.base + self.pos, f"{what} needs {n} bytes, {len(self.data) - self.pos} left")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def u8(self, what):
        return self.take(1, what)[0]

    def u16(self, what):
        return struct.unpack("<H", self.take(2, what))[0]

    def u32(self, what):
        return struct.unpack("<I", self.take(4, what))[0]

    def u64(self, what):
        return struct.unpack("<Q", self.take(8, what))[0]

    def string(self, what):
        return self.take(self.u32(what), what).decode("utf-8")

    def bytes32(self, what):
        return self.take(self.u32(what), what)

    def bytes64(self, what):
        return self.take(self.u64(what), what)

    def entries(self, what, size, fmt):
        raw = self.bytes32(what)
        if len(raw) % size:
            raise Bad(self.base + self.pos, f"{what}: {len(raw)} bytes is not a whole number of entries")
        return [struct.unpack_from(fmt, raw, i) for i in range(0, len(raw), size)]

    def string_map(self, what):
        raw = self.bytes32(what)
        inner, out = Fields(raw, self.base + self.pos - len(raw)), {}
        while inner.pos < len(raw):
            key = inner.string(what)
            if key in out:
                raise Bad(inner.base + inner.pos, f"{what}: duplicate key {key!r}")
            out[key] = inner.string(what)
        return out

    def done(self, what):
        # Records may grow new fields at the end; idms writes none, so nothing may be left.
        if self.pos != len(self.data):
            raise Bad(self.base + self.pos, f"{what}: {len(self.data) - self.pos} unexpected bytes at the end")


def records(buf, start, end):
    """(opcode, offset, content) for each record in buf[start:end], which they must fill exactly."""
    pos = start
    while pos < end:
        if end - pos < 9:
            raise Bad(pos, f"record prefix cut short ({end - pos} bytes)")
        op, length = struct.unpack_from("<BQ", buf, pos)
        if length > end - pos - 9:
            raise Bad(pos, f"record opcode {op} of {length} bytes runs past {end}")
        yield op, pos, buf[pos + 9:pos + 9 + length]
        pos += 9 + length


def parse_schema(f):
    schema = (f.u16("id"), f.string("name"), f.string("encoding"), f.bytes32("data"))
    f.done("Schema")
    if schema[0] == 0:
        raise Bad(f.base, "Schema id 0")
    return schema


def parse_channel(f):
    channel = (f.u16("id"), f.u16("schema_id"), f.string("topic"), f.string("message_encoding"),
               f.string_map("metadata"))
    f.done("Channel")
    return channel


class File:
    def __init__(self, buf):
        self.buf = buf
        self.schemas, self.channels, self.chunks, self.metadata = {}, {}, [], []
        self.messages = {}  # channel -> count
        self.times = []  # every message log time

    def define(self, table, record, offset, kind):
        old = table.setdefault(record[0], record)
        if old != record:
            raise Bad(offset, f"{kind} {record[0]} differs from an earlier record with that id")

    def add_schema(self, content, offset):
        self.define(self.schemas, parse_schema(Fields(content, offset + 9)), offset, "Schema")

    def add_channel(self, content, offset):
        channel = parse_channel(Fields(content, offset + 9))
        if channel[1] != 0 and channel[1] not in self.schemas:
            raise Bad(offset, f"Channel {channel[0]} before its Schema {channel[1]}")
        self.define(self.channels, channel, offset, "Channel")

    def message(self, content, offset):
        f = Fields(content, offset + 9)
        channel, _sequence, log_time, _publish_time = f.u16("channel_id"), f.u32("sequence"), f.u64("log_time"), \
            f.u64("publish_time")
        if channel not in self.channels:
            raise Bad(offset, f"Message on channel {channel} before its Channel record")
        return channel, log_time

    def check(self):
        buf = self.buf
        if len(buf) < 2 * len(MAGIC) + 9 + 9 + 20 or buf[:8] != MAGIC or buf[-8:] != MAGIC:
            raise Bad(0, "missing the magic at the start or the end")
        # Footer, then Header.
        footer_at = len(buf) - 8 - 29
        op, length = struct.unpack_from("<BQ", buf, footer_at)
        if op != FOOTER or length != 20:
            raise Bad(footer_at, f"expected a 20-byte Footer, found opcode {op} of {length} bytes")
        summary_start, summary_offset_start, summary_crc = struct.unpack_from("<QQI", buf, footer_at + 9)
        op, length = struct.unpack_from("<BQ", buf, 8)
        if op != HEADER:
            raise Bad(8, f"expected the Header, found opcode {op}")
        f = Fields(buf[17:17 + length], 17)
        self.profile, self.library = f.string("profile"), f.string("library")
        f.done("Header")
        data_start = 17 + length
        # The data section, up to Data End.
        data_end = summary_start if summary_start else footer_at
        seen_data_end = None
        pending_indexes = None  # the chunk whose Message Index records may follow
        for op, offset, content in records(buf, data_start, data_end):
            if seen_data_end is not None:
                raise Bad(offset, "a record after Data End in the data section")
            if op not in DATA_OPS:
                raise Bad(offset, f"opcode {op} is not allowed in the data section")
            if op == MESSAGE_INDEX:
                if pending_indexes is None:
                    raise Bad(offset, "a Message Index not right after its chunk")
                self.message_index(pending_indexes, content, offset)
                continue
            if pending_indexes is not None:
                self.end_of_indexes(pending_indexes, offset)
                pending_indexes = None
            if op == SCHEMA:
                self.add_schema(content, offset)
            elif op == CHANNEL:
                self.add_channel(content, offset)
            elif op == MESSAGE:
                channel, log_time = self.message(content, offset)
                self.messages[channel] = self.messages.get(channel, 0) + 1
                self.times.append(log_time)
            elif op == CHUNK:
                pending_indexes = self.chunk(content, offset)
            elif op == METADATA:
                f = Fields(content, offset + 9)
                self.metadata.append((offset, 9 + len(content), f.string("name"), f.string_map("metadata")))
                f.done("Metadata")
            elif op == DATA_END:
                f = Fields(content, offset + 9)
                crc = f.u32("data_section_crc")
                if crc and crc != zlib.crc32(buf[:offset]):
                    raise Bad(offset, f"data section CRC {crc:#010x}, computed {zlib.crc32(buf[:offset]):#010x}")
                seen_data_end = offset
        if pending_indexes is not None:
            self.end_of_indexes(pending_indexes, data_end)
        if seen_data_end is None:
            raise Bad(data_end, "no Data End record ends the data section")
        if summary_start:
            self.summary(summary_start, summary_offset_start or footer_at, summary_offset_start, footer_at)
        elif summary_offset_start:
            raise Bad(footer_at, "summary offsets without a summary")
        if summary_crc and summary_crc != zlib.crc32(buf[summary_start:footer_at + 9 + 16]):
            raise Bad(footer_at, "summary CRC mismatch")
        return self

    def chunk(self, content, offset):
        f = Fields(content, offset + 9)
        start, end, size, crc = f.u64("message_start_time"), f.u64("message_end_time"), f.u64("uncompressed_size"), \
            f.u32("uncompressed_crc")
        compression = f.string("compression")
        stored = f.bytes64("records")
        f.done("Chunk")
        chunk = {"offset": offset, "length": 9 + len(content), "start": start, "end": end, "size": size,
                 "compression": compression, "compressed": len(stored), "indexes": {}, "index_end": None,
                 "messages": None, "times": []}
        if compression == "":
            if len(stored) != size:
                raise Bad(offset, f"uncompressed chunk of {len(stored)} bytes declares {size}")
            if crc and zlib.crc32(stored) != crc:
                raise Bad(offset, f"chunk CRC {crc:#010x}, computed {zlib.crc32(stored):#010x}")
            messages = {}  # record offset -> (channel, log time)
            for op, at, inner in records(stored, 0, len(stored)):
                if op not in CHUNK_OPS:
                    raise Bad(offset, f"opcode {op} inside a chunk (records offset {at})")
                if op == SCHEMA:
                    self.add_schema(inner, offset)
                elif op == CHANNEL:
                    self.add_channel(inner, offset)
                else:
                    messages[at] = self.message(inner, offset)
            times = [t for _, t in messages.values()]
            if messages and (min(times) != start or max(times) != end):
                raise Bad(offset, f"chunk times {start}..{end}, its messages {min(times)}..{max(times)}")
            chunk["messages"] = messages
        elif compression != "zstd":
            raise Bad(offset, f"unknown compression {compression!r}")
        self.chunks.append(chunk)
        return chunk

    def message_index(self, chunk, content, offset):
        f = Fields(content, offset + 9)
        channel = f.u16("channel_id")
        entries = f.entries("records", 16, "<QQ")
        f.done("MessageIndex")
        if channel in chunk["indexes"]:
            raise Bad(offset, f"a second Message Index for channel {channel} after one chunk")
        if channel not in self.channels:
            raise Bad(offset, f"Message Index for undefined channel {channel}")
        chunk["indexes"][channel] = offset
        chunk["index_end"] = offset + 9 + len(content)
        for log_time, record_offset in entries:
            if not chunk["start"] <= log_time <= chunk["end"] or record_offset >= chunk["size"]:
                raise Bad(offset, f"entry ({log_time}, {record_offset}) outside its chunk")
            if chunk["messages"] is not None and chunk["messages"].get(record_offset) != (channel, log_time):
                raise Bad(offset, f"entry ({log_time}, {record_offset}) is not a Message on channel {channel} then")
            chunk["times"].append((record_offset, channel, log_time))

    def end_of_indexes(self, chunk, offset):
        # Every message indexed exactly once, one index per channel present.
        offsets = sorted(o for o, _, _ in chunk["times"])
        if len(set(offsets)) != len(offsets):
            raise Bad(offset, f"chunk at {chunk['offset']}: a message indexed twice")
        if chunk["messages"] is not None:
            if set(offsets) != set(chunk["messages"]):
                raise Bad(offset, f"chunk at {chunk['offset']}: its message indexes do not list every message")
            if set(c for c, _ in chunk["messages"].values()) != set(chunk["indexes"]):
                raise Bad(offset, f"chunk at {chunk['offset']}: Message Index records differ from its channels")
        times = [t for _, _, t in chunk["times"]]
        if times and (min(times) != chunk["start"] or max(times) != chunk["end"]):
            raise Bad(offset, f"chunk at {chunk['offset']}: time range differs from its indexed messages")
        for _, channel, log_time in chunk["times"]:
            self.messages[channel] = self.messages.get(channel, 0) + 1
            self.times.append(log_time)

    def summary(self, start, end, offsets_start, footer_at):
        buf = self.buf
        groups, order, statistics = {}, [], None
        schemas, channels, chunk_indexes, metadata_indexes = {}, {}, [], []
        for op, offset, content in records(buf, start, end):
            if op not in SUMMARY_OPS:
                raise Bad(offset, f"opcode {op} is not allowed in the summary")
            if order and order[-1] != op and op in groups:
                raise Bad(offset, f"summary records of opcode {op} are not grouped together")
            if op not in groups:
                order.append(op)
                groups[op] = [offset, 0]
            groups[op][1] = offset + 9 + len(content) - groups[op][0]
            f = Fields(content, offset + 9)
            if op == SCHEMA:
                schema = parse_schema(f)
                if self.schemas.get(schema[0]) != schema:
                    raise Bad(offset, f"summary Schema {schema[0]} differs from the data section's")
                schemas[schema[0]] = schema
            elif op == CHANNEL:
                channel = parse_channel(f)
                if self.channels.get(channel[0]) != channel:
                    raise Bad(offset, f"summary Channel {channel[0]} differs from the data section's")
                channels[channel[0]] = channel
            elif op == CHUNK_INDEX:
                chunk_indexes.append((offset, (f.u64("message_start_time"), f.u64("message_end_time"),
                                               f.u64("chunk_start_offset"), f.u64("chunk_length"),
                                               dict(f.entries("message_index_offsets", 10, "<HQ")),
                                               f.u64("message_index_length"), f.string("compression"),
                                               f.u64("compressed_size"), f.u64("uncompressed_size"))))
                f.done("ChunkIndex")
            elif op == METADATA_INDEX:
                metadata_indexes.append((f.u64("offset"), f.u64("length"), f.string("name")))
                f.done("MetadataIndex")
            elif op == STATISTICS:
                if statistics is not None:
                    raise Bad(offset, "a second Statistics record")
                statistics = (offset, f.u64("message_count"), f.u16("schema_count"), f.u32("channel_count"),
                              f.u32("attachment_count"), f.u32("metadata_count"), f.u32("chunk_count"),
                              f.u64("message_start_time"), f.u64("message_end_time"),
                              dict(f.entries("channel_message_counts", 10, "<HQ")))
                f.done("Statistics")
                if any(c not in channels for c in statistics[9]):
                    raise Bad(offset, "Statistics counts a channel whose Channel record does not precede it")
        # Chunk indexes: one per chunk, each matching it.
        if len(chunk_indexes) != len(self.chunks):
            raise Bad(start, f"{len(chunk_indexes)} Chunk Index records for {len(self.chunks)} chunks")
        for (offset, index), chunk in zip(chunk_indexes, self.chunks):
            expected = (chunk["start"], chunk["end"], chunk["offset"], chunk["length"], chunk["indexes"],
                        (chunk["index_end"] or chunk["offset"] + chunk["length"]) - chunk["offset"] - chunk["length"],
                        chunk["compression"], chunk["compressed"], chunk["size"])
            if index != expected:
                raise Bad(offset, f"Chunk Index {index} does not match the chunk {expected}")
            for channel in index[4]:
                if channel not in channels or (channels[channel][1] and channels[channel][1] not in schemas):
                    raise Bad(offset, f"channel {channel} of a Chunk Index lacks its Channel/Schema in the summary")
        # Metadata indexes.
        found = [(o, n, name) for o, n, name, _ in self.metadata]
        if sorted(metadata_indexes) != sorted(found):
            raise Bad(start, f"Metadata Index records {metadata_indexes} do not match the Metadata {found}")
        # Statistics.
        if statistics is not None:
            times = self.times
            expected = (sum(self.messages.values()), len(self.schemas), len(self.channels), 0, len(self.metadata),
                        len(self.chunks), min(times) if times else 0, max(times) if times else 0)
            if statistics[1:9] != expected:
                raise Bad(statistics[0], f"Statistics {statistics[1:9]} do not match the file {expected}")
            counts = {c: n for c, n in statistics[9].items() if n}
            if statistics[9] and counts != self.messages:
                raise Bad(statistics[0], f"channel_message_counts {counts} do not match the file {self.messages}")
        # Summary offsets: one per group, matching it.
        if offsets_start:
            listed = {}
            for op, offset, content in records(buf, offsets_start, footer_at):
                if op != SUMMARY_OFFSET:
                    raise Bad(offset, f"opcode {op} in the summary offset section")
                f = Fields(content, offset + 9)
                group = f.u8("group_opcode")
                listed[group] = [f.u64("group_start"), f.u64("group_length")]
                f.done("SummaryOffset")
            if listed != groups:
                raise Bad(offsets_start, f"Summary Offsets {listed} do not match the summary groups {groups}")


def describe(path, checked):
    zstd = sum(1 for c in checked.chunks if c["compression"] == "zstd")
    return (f"OK {path}: {sum(checked.messages.values())} messages on {len(checked.channels)} channels, "
            f"{len(checked.chunks)} chunks ({zstd} zstd, not decompressed), {len(checked.metadata)} metadata")


def self_test(path):
    """Damaged copies of an uncompressed file must each be rejected."""
    buf = open(path, "rb").read()
    checked = File(buf).check()
    chunk = checked.chunks[len(checked.chunks) // 2]
    if chunk["compression"] != "":
        sys.exit(f"{path}: --self-test needs a file written without compression")
    footer_at = len(buf) - 37
    damages = {
        "a byte of a chunk's records": chunk["offset"] + 49 + 40,
        "a byte of a message index": chunk["offset"] + chunk["length"] + 9 + 2 + 4 + 1,
        "a byte of the summary": struct.unpack_from("<Q", buf, footer_at + 9)[0] + 30,
        "the footer's summary offset": footer_at + 9 + 8,
    }
    for what, at in damages.items():
        damaged = bytearray(buf)
        damaged[at] ^= 0x5A
        try:
            File(bytes(damaged)).check()
        except Bad as e:
            print(f"rejected ({what}): {e}")
            continue
        sys.exit(f"{path}: damaging {what} at byte {at} was not detected")
    try:
        File(buf[:chunk["offset"] + 100]).check()
        sys.exit(f"{path}: a truncated copy was not detected")
    except Bad as e:
        print(f"rejected (truncated): {e}")
    print(f"OK self-test {path}")


def main(argv):
    if len(argv) == 3 and argv[1] == "--self-test":
        self_test(argv[2])
        return 0
    if len(argv) < 2:
        print(__doc__)
        return 2
    for path in argv[1:]:
        try:
            print(describe(path, File(open(path, "rb").read()).check()))
        except (Bad, UnicodeDecodeError, struct.error) as e:
            print(f"FAIL {path}: {e}")
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
