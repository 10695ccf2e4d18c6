// A node-opcua client, as an MES built on that stack would be: subscribes to events at the
// Server object, prints "ready", then one JSON line per event that carries a Result
// (what node-opcua decoded of it), and stops after COUNT of them.
//
//   node tests/opcua/node_client.mjs URL COUNT [--fix] [--reconnect] [--of-type]
//
// --fix: the client-side fix for node-opcua's optional-bit numbering of subtypes (see
// fixOptionalBits): its schema builder starts a subtype's own optional bits at the number of
// all its base type's fields, mandatory ones included; Part 6 numbers optional fields only.
// The module is looked up from NODE_PATH's folder (the test installs it into a cache).
import { createRequire } from "node:module";
import path from "node:path";

const require = createRequire(path.join(process.env.NODE_OPCUA_DIR || process.cwd(), "x.js"));
const opcua = await import(require.resolve("node-opcua"));
const { OPCUAClient, AttributeIds, constructEventFilter, TimestampsToReturn,
        MessageSecurityMode, SecurityPolicy, ofType } = opcua;

const [url, countText, ...flags] = process.argv.slice(2);
const count = Number(countText);
const IJT = "http://opcfoundation.org/UA/IJT/Base/";

function plain(v) {
  if (v === null || v === undefined) return null;
  if (typeof v === "bigint") return Number(v);
  if (Array.isArray(v) || ArrayBuffer.isView(v)) return Array.from(v, plain);
  if (typeof v === "number" && Number.isNaN(v)) return null;
  if (typeof v !== "object") return v;
  if (v instanceof Date) return v.toISOString();
  if (v.text !== undefined && v.locale !== undefined) return v.text;
  if (v.value !== undefined && v.dataType !== undefined) return plain(v.value);   // a Variant
  if (v.low !== undefined && v.high !== undefined && Object.keys(v).length <= 3) return v.high * 4294967296 + v.low;
  const out = {};
  const schema = v.schema;
  const types = {};
  for (let s = schema; s; s = s._baseSchema || null) {
    for (const f of s.fields || []) types[f.name] = f.fieldType;
  }
  for (const key of Object.keys(v)) {
    if (key === "schema" || key.startsWith("_")) continue;
    const value = v[key];
    if (value === undefined) continue;
    const name = key.charAt(0).toUpperCase() + key.slice(1);
    const type = types[key] || types[name];
    out[name] = (type === "UInt64" || type === "Int64") && Array.isArray(value)
      ? value[0] * 4294967296 + value[1] : plain(value);
  }
  if (schema && schema.name) out._type = schema.name;
  return out;
}

// Part 6: bit n of a structure's EncodingMask is its n-th optional field, counting the base
// type's optional fields only.  node-opcua (2.182 to 2.186 at least) counts every base field
// for a subtype's own optional bits; renumbering its schemas' switchBit restores Part 6.
function fixOptionalBits(dataTypeManager) {
  // every schema the session built, by name (the factories' own maps: asking a factory for
  // a name it lacks recurses through its base factories for ever in 2.186)
  const byName = new Map();
  for (const factory of Object.values(dataTypeManager.dataTypeFactoryMapByNamespace)) {
    for (const info of factory.getStructureIterator()) byName.set(info.schema.name, info.schema);
  }
  const optionalIn = (schema) => {
    let n = 0;
    for (let s = schema; s; s = byName.get(s.baseType)) {
      n += s.fields.filter((f) => f.switchBit !== undefined).length;
    }
    return n;
  };
  let fixed = 0;
  for (const schema of byName.values()) {
    const base = byName.get(schema.baseType);
    let bit = base ? optionalIn(base) : 0;
    for (const f of schema.fields) {
      if (f.switchBit === undefined) continue;
      if (f.switchBit !== bit) { f.switchBit = bit; fixed++; }
      bit++;
    }
  }
  return fixed;
}

// --reconnect: keep reconnecting as a long-running MES does (node-opcua's own session and
// subscription recovery), e.g. across a reload of the station that restarts its server
const reconnect = flags.includes("--reconnect");
const client = OPCUAClient.create({ endpointMustExist: false,
  connectionStrategy: reconnect ? { maxRetry: 1000, initialDelay: 200, maxDelay: 1000 }
                                : { maxRetry: 2 },
  securityMode: MessageSecurityMode.None, securityPolicy: SecurityPolicy.None });
await client.connect(url);
const session = await client.createSession();
const ns = await session.readNamespaceArray();
const ijt = ns.indexOf(IJT);
if (flags.includes("--fix")) {
  const { getExtraDataTypeManager } = opcua;
  const manager = await getExtraDataTypeManager(session);
  process.stderr.write(`renumbered ${fixOptionalBits(manager)} optional bits\n`);
}
const subscription = await session.createSubscription2({ requestedPublishingInterval: 50,
  requestedLifetimeCount: 1000, requestedMaxKeepAliveCount: 10, publishingEnabled: true });
const fields = ["EventType", "Message", "SourceName", `${ijt}:Result`];
// --of-type: only JoiningSystemResultReadyEventType's events (and its subtypes', Part 4
// 7.7.3), by a where clause, as an MES that filters on the server does
const where = flags.includes("--of-type") ? ofType(`ns=${ijt};i=1007`) : undefined;
const item = await subscription.monitor(
  { nodeId: "i=2253", attributeId: AttributeIds.EventNotifier },
  { samplingInterval: 0, queueSize: 1000, filter: constructEventFilter(fields, where) },
  TimestampsToReturn.Neither);
let seen = 0;
const done = new Promise((resolve) => {
  item.on("changed", async (values) => {
    const result = values[3];
    if (!result || result.value === null) return;
    const { promoteOpaqueStructure } = opcua;
    if (promoteOpaqueStructure) await promoteOpaqueStructure(session, [{ value: result }]);
    let decoded;
    try {
      decoded = plain(result.value);
    } catch (e) {
      decoded = { failed: String(e) };
    }
    console.log(JSON.stringify({ message: plain(values[1].value), result: decoded }));
    seen++;
    if (seen >= count) resolve();
  });
});
console.log("ready");
await done;
await subscription.terminate();
await session.close();
await client.disconnect();
