// Reads a TAK data package with @tak-ps/node-cot's DataPackage (never deleting it: the
// parser's default `cleanup` removes its input) and prints what a TAK client would import.
import { DataPackage } from '@tak-ps/node-cot';
const pkg = await DataPackage.parse(process.argv[2], { cleanup: false });
const cots = [];
for (const cot of await pkg.cots()) {
  const detail = cot.raw.event.detail || {};
  cots.push({
    uid: cot.uid(),
    type: cot.raw.event._attributes.type,
    callsign: cot.callsign(),
    stale: cot.raw.event._attributes.stale,
    point: cot.raw.event.point._attributes,
    remarks: detail.remarks ? detail.remarks._text : null,
    attachment_hashes: detail.attachment_list ? JSON.parse(detail.attachment_list._attributes.hashes) : [],
    archived: 'archive' in detail,
    geojson: await cot.to_geojson(),
  });
}
const attachments = {};
for (const [uid, contents] of (await pkg.attachments()).entries()) {
  attachments[uid] = contents.map((c) => c._attributes.zipEntry);
}
const hashes = {};
for (const entries of Object.values(attachments)) {
  for (const e of entries) hashes[e] = await pkg.hash(e);
}
console.log(JSON.stringify({
  version: pkg.version,
  settings: pkg.settings,
  cots,
  attachments,
  hashes,
  files: [...(await pkg.files())],
}));
await pkg.destroy();
