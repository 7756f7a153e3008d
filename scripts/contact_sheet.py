#!/usr/bin/env python3
"""Tiles PNG images into one contact sheet, standard library only (for
`make sunsets`): contact_sheet.py [--scale K] OUT.png COLUMNS IN1.png IN2.png ...
Images are laid out row by row, COLUMNS per row, with a 4-pixel black
gutter; --scale K enlarges the sheet K times, each pixel a K×K block (for
small renders). Reads 8-bit RGB or RGBA, non-interlaced PNGs (what `sky` writes)."""
import struct
import sys
import zlib


def read_png(path):
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat, w = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and ctype in (2, 6) and interlace == 0, f"{path}: unsupported PNG"
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += n + 12
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line[j] for j in range(stride) if j % bpp < 3))
        prev = line
    return w, h, rows


def write_png(path, w, h, rows):
    raw = b"".join(b"\x00" + r for r in rows)
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    open(path, "wb").write(png)


def main():
    args = sys.argv[1:]
    scale = 1
    if args[:1] == ["--scale"]:
        scale, args = int(args[1]), args[2:]
    out, cols, ins = args[0], int(args[1]), args[2:]
    imgs = [read_png(p) for p in ins]
    w, h = imgs[0][0], imgs[0][1]
    g = 4
    nrows = (len(imgs) + cols - 1) // cols
    W, H = cols * w + (cols - 1) * g, nrows * h + (nrows - 1) * g
    sheet = [bytearray(3 * W) for _ in range(H)]
    for k, (iw, ih, rows) in enumerate(imgs):
        assert (iw, ih) == (w, h), "images must share one size"
        x0, y0 = (k % cols) * (w + g), (k // cols) * (h + g)
        for y in range(h):
            sheet[y0 + y][3 * x0:3 * (x0 + w)] = rows[y]
    if scale > 1:
        big = []
        for r in sheet:
            line = b"".join(bytes(r[3 * x:3 * x + 3]) * scale for x in range(W))
            big.extend([line] * scale)
        write_png(out, W * scale, H * scale, big)
    else:
        write_png(out, W, H, [bytes(r) for r in sheet])


if __name__ == "__main__":
    main()
