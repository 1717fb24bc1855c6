import CoT from '@tak-ps/node-cot';
import { readFileSync } from 'fs';
const out = [];
for (const line of readFileSync(0, 'utf8').split('\n')) {
  if (!line.trim()) continue;
  const cot = new CoT(line);
  const gj = await cot.to_geojson();
  out.push({ raw: cot.raw.event._attributes, point: cot.raw.event.point._attributes, geojson: gj });
}
console.log(JSON.stringify(out));
