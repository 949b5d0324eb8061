"""Multi-frame diagnostic responses (ISO-TP, ISO 15765-2) in a raw CAN bus log, decoded with a DBC.

An electric car's battery current, voltage and state of charge reach an OBD logger as UDS
responses (service 0x22, ``ReadDataByIdentifier``) of tens of bytes, each split over a
*first frame* and *consecutive frames* of 8 bytes on one CAN ID (a Hyundai Kona's battery
management system answers DID 0x0101 on 0x7EC in 62 bytes). A DBC file describes such a
response as one message longer than 8 bytes, multiplexed on the service and the DID.
asammdf decodes each 8-byte frame on its own, so these messages are reassembled here first:

* **Which messages:** a DBC message longer than 8 bytes whose CAN ID the log carries in
  frames of at most 8 bytes (a CAN FD message of that length arrives whole and is left to
  asammdf).
* **Reassembly**, per bus and CAN ID in time order: a single frame (PCI 0x0N) is a whole
  response of N bytes; a first frame (0x1N NN: 12-bit length) opens one, consecutive frames
  (0x2N, N the sequence number 1, 2, …, 15, 0, …) continue it until its length is reached.
  A frame out of sequence drops the response it would continue (a lost frame), as does a
  first frame whose consecutive frames never come (the tester stopped sending flow
  control); both are counted. The response is time-stamped with its first frame.
* **Byte layout** of the reassembled response, as the DBC numbers its bytes
  (``[options] isotp_layout``): ``"css"`` (the default) — byte 0 the length's low byte,
  then the response (service id 0x62 at byte 1, DID at bytes 2–3): CSS Electronics' layout,
  in which their public UDS DBC files are written; ``"payload"`` — the response alone
  (service id at byte 0), the ISO 15765-2 payload as Vector's TP DBC messages define it.
* **Decoding** is asammdf's own (``bus_logging_utils.extract_mux``, multiplexing included),
  on the reassembled bytes, zero-padded to the message's length; its signals join the
  decoded file under their DBC names (and ``MESSAGE.Signal``), as the other messages'.

Checked on a real CANedge log of a Hyundai Kona Electric (CSS Electronics' public examples)
with CSS's UDS DBC: tests/test_mdf_isotp.py.
"""

from __future__ import annotations

import numpy as np

#: byte layouts of a reassembled response (see the module docstring); the first is the default
LAYOUTS = ("css", "payload")


def reassemble(t: np.ndarray, data: np.ndarray, length: np.ndarray, layout: str = "css"):
    """The responses of one CAN ID's frames (times ``t``, bytes ``data`` n × ≥ 8, data
    lengths ``length``) in time order → (times of their first frames, list of bytes,
    number of responses left incomplete: a frame out of sequence, a first frame whose
    consecutive frames never came)."""
    times, out, broken = [], [], 0
    open_ = None  # [time, size, bytearray, next sequence number]
    for ti, row, k in zip(t.tolist(), data.tolist(), length.tolist()):
        k = min(int(k), len(row))
        if k < 1:
            continue
        pci = row[0] >> 4
        if pci == 0:  # single frame: the whole response
            size = row[0] & 0x0F
            if 1 <= size <= k - 1:
                times.append(ti)
                out.append(bytes(row[:1 + size]) if layout == "css" else bytes(row[1:1 + size]))
            broken += open_ is not None
            open_ = None
        elif pci == 1 and k >= 2:  # first frame: a 12-bit length, then the first bytes
            broken += open_ is not None
            size = ((row[0] & 0x0F) << 8) | row[1]
            open_ = [ti, size, bytearray(row[2:k]), 1] if size > 7 else None
        elif pci == 2 and open_ is not None:  # consecutive frame
            if row[0] & 0x0F != open_[3]:
                open_, broken = None, broken + 1
                continue
            open_[2] += bytes(row[1:k])
            open_[3] = (open_[3] + 1) & 0x0F
            if len(open_[2]) >= open_[1]:
                body = bytes(open_[2][:open_[1]])
                times.append(open_[0])
                out.append(bytes([open_[1] & 0xFF]) + body if layout == "css" else body)
                open_ = None
        # 0x3N: flow control (the logger's or tester's own request side): not a response
    broken += open_ is not None  # unfinished when the log ends
    return np.asarray(times, float), out, broken


def _frames(mdf):
    """(bus, time, id, data bytes, data length) arrays of every CAN data frame group."""
    for g, i in mdf.channels_db.get("CAN_DataFrame.ID", ()):
        ids = mdf.get("CAN_DataFrame.ID", group=g, index=i)
        data = np.asarray(mdf.get("CAN_DataFrame.DataBytes", group=g).samples)
        try:
            n = np.asarray(mdf.get("CAN_DataFrame.DataLength", group=g).samples, int)
        except Exception:  # a logger without the channel: the bytes' width
            n = np.full(len(data), data.shape[1] if data.ndim == 2 else 8)
        try:
            bus = np.asarray(mdf.get("CAN_DataFrame.BusChannel", group=g).samples, int)
        except Exception:
            bus = np.ones(len(data), int)
        yield bus, np.asarray(ids.timestamps, float), np.asarray(ids.samples, np.int64) & 0x1FFFFFFF, data, n


def split_databases(mdf, dbc_files):
    """The DBC files as canmatrix databases without their ISO-TP messages, and those
    messages: ``(databases, {can id: message})`` (see the module docstring: longer than 8
    bytes, carried by the log in frames of at most 8 bytes)."""
    from asammdf.blocks.utils import load_can_database

    dbs = [load_can_database(str(f)) for f in dbc_files]
    long = {f.arbitration_id.id: f for db in dbs for f in db.frames if f.size > 8}
    if not long:
        return dbs, {}
    short_ids = set()
    for _, _, ids, _, n in _frames(mdf):
        for cid in long:
            sel = ids == cid
            if sel.any() and int(n[sel].max()) <= 8:
                short_ids.add(cid)
    tp = {cid: long[cid] for cid in short_ids}
    for db in dbs:
        for f in [f for f in db.frames if f.arbitration_id.id in tp]:
            db.del_frame(f)
    return dbs, tp


def decode_into(out, mdf, messages: dict, layout: str = "css") -> dict:
    """Reassemble the ISO-TP ``messages`` ({can id: canmatrix frame}) from the raw frames of
    ``mdf`` and append their decoded signals to ``out`` (an asammdf MDF). Returns
    {message name: [responses decoded, responses dropped for a lost frame]}."""
    from asammdf import Signal
    from asammdf.blocks.bus_logging_utils import extract_mux

    counts: dict[str, list[int]] = {}
    for bus, t, ids, data, n in _frames(mdf):
        for b in np.unique(bus).tolist():
            on = bus == b
            for cid, msg in messages.items():
                sel = on & (ids == cid)
                if not sel.any():
                    continue
                order = np.argsort(t[sel], kind="stable")
                times, resp, broken = reassemble(t[sel][order], data[sel][order], n[sel][order], layout)
                c = counts.setdefault(msg.name, [0, 0])
                c[0], c[1] = c[0] + len(resp), c[1] + broken
                if not resp:
                    continue
                payload = np.zeros((len(resp), msg.size), np.uint8)
                for j, r in enumerate(resp):
                    payload[j, :min(len(r), msg.size)] = np.frombuffer(r[:msg.size], np.uint8)
                for signals in extract_mux(payload, msg, cid, b, times, raw=True).values():
                    sigs = [Signal(samples=s["samples"], timestamps=s["t"], name=s["name"], unit=s["unit"],
                                   comment=s["comment"], conversion=s["conversion"],
                                   invalidation_bits=s["invalidation_bits"],
                                   display_names={f"CAN{b}.{msg.name}.{s['name']}": "bus",
                                                  f"{msg.name}.{s['name']}": "message"})
                            for s in signals.values() if len(s["samples"])]
                    if sigs:
                        out.append(sigs, acq_name=f"CAN{b} ISO-TP 0x{cid:X} {msg.name}", common_timebase=True)
    return counts
