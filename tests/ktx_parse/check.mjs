// Reads a KTX2 file with ktx-parse (an independent reader: the npm package
// three.js and glTF-Transform use) and prints what it found as JSON, for
// tests/ktx_readers.rs. Set up with `npm ci --prefix tests/ktx_parse`
// (`make test` does it).
//
//   node tests/ktx_parse/check.mjs FILE.ktx2 [--data]
//
// keyValue is a list of [key, value] pairs in file order (ktx-parse keeps the
// order of the file); values are decoded as UTF-8 text with ktx-parse's own
// handling for KTX* keys (trailing NUL removed) and, for other keys, the raw
// bytes decoded as UTF-8 (NUL kept). --data adds level 0 as hex.
import { readFileSync } from 'node:fs';
import { read } from 'ktx-parse';

const [file, flag] = process.argv.slice(2);
if (!file) {
	console.error('usage: node check.mjs FILE.ktx2 [--data]');
	process.exit(2);
}
const bytes = new Uint8Array(readFileSync(file));
const c = read(bytes);
const text = (v) => (typeof v === 'string' ? v : new TextDecoder('utf-8', { fatal: true }).decode(v));
const out = {
	vkFormat: c.vkFormat,
	typeSize: c.typeSize,
	pixelWidth: c.pixelWidth,
	pixelHeight: c.pixelHeight,
	pixelDepth: c.pixelDepth,
	layerCount: c.layerCount,
	faceCount: c.faceCount,
	levelCount: c.levelCount,
	supercompressionScheme: c.supercompressionScheme,
	levels: c.levels.map((l) => ({
		byteOffset: l.levelData.byteOffset,
		byteLength: l.levelData.byteLength,
		uncompressedByteLength: l.uncompressedByteLength,
	})),
	dataFormatDescriptor: c.dataFormatDescriptor,
	keyValue: Object.entries(c.keyValue).map(([k, v]) => [k, text(v)]),
	fileByteLength: bytes.byteLength,
};
if (flag === '--data') {
	out.level0Hex = Buffer.from(c.levels[0].levelData).toString('hex');
}
process.stdout.write(JSON.stringify(out) + '\n');
