// Validates deploy/k8s offline: every object against the Kubernetes OpenAPI schemas (kubernetes-
// models 4.5.1, Kubernetes 1.30+ API; the ServiceMonitor against the prometheus-operator CRD via
// @kubernetes-models/prometheus-operator), then the deployment's own invariants (readiness on
// /readyz, grace period = preStop + drain + margin, no fixed replicas, no affinity, ...), and
// that the HPA's metric is the one the prometheus-adapter rule exposes.
// The schema check covers types, formats (quantities, int32), enums and required fields; the
// compiled validators let unknown field names through, so a second walk (unknownFields) checks
// every field name against the models' TypeScript declarations (the interfaces the validators
// were generated from), as kubeconform -strict would (it is not packaged for Debian 12).
// usage: node validate_k8s.mjs [REPO]. Exit 0 all pass, 1 a failure, 77 (SKIP) without npm ci.
import { existsSync, readFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(process.argv[2] || path.join(here, '../..'));
if (!existsSync(path.join(here, 'node_modules/kubernetes-models'))) {
  console.log('SKIP: tests/deploy/node_modules missing (run bash scripts/setup_web.sh)');
  process.exit(77);
}
const { parseAllDocuments, parse } = await import('yaml');

let failures = 0;
const check = (what, ok, detail = '') => {
  console.log(`${ok ? 'ok' : 'FAIL'}: ${what}${ok || !detail ? '' : ` (${detail})`}`);
  if (!ok) failures++;
};

// The model class for apiVersion/kind, or null when no schema is known.
async function modelClass(apiVersion, kind) {
  const [group, version] = apiVersion.includes('/') ? apiVersion.split('/') : ['', apiVersion];
  const mod = group === 'monitoring.coreos.com'
    ? `@kubernetes-models/prometheus-operator/${group}/${version}`
    : `kubernetes-models/${group ? `${group}/` : ''}${version}`;
  try {
    return (await import(mod))[kind] || null;
  } catch {
    return null;
  }
}

// Throws the schema errors of `obj`.
async function validate(obj) {
  const Model = await modelClass(obj.apiVersion, obj.kind);
  if (!Model) throw new Error(`no schema for ${obj.apiVersion} ${obj.kind}`);
  new Model(obj).validate();
}

// The .d.ts beside the module `spec` imports (relative to `from`), or null: a relative path, a
// package subpath node resolves, or one its "exports" map does not list (found in node_modules
// folders above `from`).
function declarations(spec, from, req) {
  const dtsOf = (js) => js.replace(/\.(c|m)?js$/, '') + '.d.ts';
  if (spec.startsWith('.')) return dtsOf(path.resolve(path.dirname(from), spec));
  try {
    const dts = dtsOf(req.resolve(spec));
    if (existsSync(dts)) return dts;
  } catch {
    // not exported: look for the file itself
  }
  for (let dir = path.dirname(from); dir !== path.dirname(dir); dir = path.dirname(dir)) {
    const dts = path.join(dir, 'node_modules', `${spec}.d.ts`);
    if (existsSync(dts)) return dts;
  }
  return null;
}

// The field names and types of the interface a model's .d.ts declares first, and where its
// imported interfaces live: { props: Map(name -> type text), imports: Map(type name -> .d.ts) }.
const interfaces = new Map();
function interfaceOf(dts) {
  if (interfaces.has(dts)) return interfaces.get(dts);
  const text = readFileSync(dts, 'utf8');
  const req = createRequire(dts);
  const imports = new Map();
  for (const m of text.matchAll(/^import \{ ([^}]+) \} from "([^"]+)";$/gm)) {
    const target = declarations(m[2], dts, req);
    for (const name of m[1].split(',').map((s) => s.trim())) imports.set(name, target);
  }
  const body = text.match(/^export interface \w+(?: extends [\w, ]+)? \{\n([\s\S]*?)^\}/m);
  const props = new Map();
  // A field's type is one line, or an object type over several ({ [key: string]: string; }).
  for (const m of (body ? body[1] : '').matchAll(/^ {4}"([^"]+)"\??: (\{[\s\S]*?^ {4}\}|[^\n]+?);$/gm))
    props.set(m[1], m[2].replace(/\s+/g, ' '));
  const r = { props, imports };
  interfaces.set(dts, r);
  return r;
}

// Field names of `value` (at `where`) that its type `type` (declared in `dts`) does not have.
function unknownFields(value, type, dts, where, out) {
  if (value === null || typeof value !== 'object') return out;
  const array = type.match(/^Array<(.+)>$/);
  if (array) {
    if (Array.isArray(value)) value.forEach((v, i) => unknownFields(v, array[1], dts, `${where}[${i}]`, out));
    return out;
  }
  const map = type.match(/^\{\s*\[key: string\]: (.+?);?\s*\}$/);
  if (map) {
    for (const [k, v] of Object.entries(value)) unknownFields(v, map[1], dts, `${where}.${k}`, out);
    return out;
  }
  const target = interfaceOf(dts).imports.get(type);
  if (!target) return out;  // a primitive, a union or a type not imported here: no fields to check
  const { props } = interfaceOf(target);
  for (const [k, v] of Object.entries(value)) {
    if (!props.has(k)) out.push(`${where}.${k}`);
    else unknownFields(v, props.get(k), target, `${where}.${k}`, out);
  }
  return out;
}

// The top-level object against its kind's interface.
function unknownTopLevel(obj) {
  const [group, version] = obj.apiVersion.includes('/') ? obj.apiVersion.split('/') : ['', obj.apiVersion];
  const mod = group === 'monitoring.coreos.com'
    ? `@kubernetes-models/prometheus-operator/${group}/${version}/${obj.kind}`
    : `kubernetes-models/${group ? `${group}/` : ''}${version}/${obj.kind}`;
  const dts = declarations(mod, path.join(here, 'x.mjs'), createRequire(path.join(here, 'x.mjs')));
  if (!dts) throw new Error(`no declarations for ${mod}`);
  const { props } = interfaceOf(dts);
  const out = [];
  for (const [k, v] of Object.entries(obj)) {
    if (!props.has(k)) out.push(k);
    else unknownFields(v, props.get(k), dts, k, out);
  }
  return out;
}

const file = path.join(repo, 'deploy/k8s/catgs-stream.yaml');
const docs = parseAllDocuments(readFileSync(file, 'utf8'));
const objects = [];
for (const d of docs) {
  check(`YAML parses (document ${objects.length + 1})`, d.errors.length === 0, d.errors.map(String).join('; '));
  objects.push(d.toJS());
}
for (const o of objects) {
  try {
    await validate(o);
    check(`${o.kind}/${o.metadata?.name} matches the ${o.apiVersion} schema`, true);
  } catch (e) {
    check(`${o.kind}/${o.metadata?.name} matches the ${o.apiVersion} schema`, false, e.message.slice(0, 600));
  }
}

for (const o of objects) {
  let unknown;
  try {
    unknown = unknownTopLevel(o);
  } catch (e) {
    unknown = [`(no declarations: ${e.message})`];
  }
  check(`${o.kind}/${o.metadata?.name} has no unknown field names`, unknown.length === 0, unknown.join(', '));
}

// The validator is live: a wrong type must be refused.
const byKind = (k) => objects.find((o) => o.kind === k);
const dep = byKind('Deployment');
const broken = structuredClone(dep);
broken.spec.template.spec.containers[0].ports[0].containerPort = 'eighty';
let refused = false;
try {
  await validate(broken);
} catch {
  refused = true;
}
check('the schema check refuses a string containerPort (self-test)', refused);
// The field-name walk is live: misspelt fields, deep in a pod template and in a map's values,
// are named.
const misspelt = structuredClone(dep);
misspelt.spec.template.spec.containers[0].readinessProbes = misspelt.spec.template.spec.containers[0].readinessProbe;
misspelt.spec.template.metadata.lables = { a: 'b' };
const named = unknownTopLevel(misspelt);
check('the field-name walk names misspelt fields (self-test)',
  named.includes('spec.template.spec.containers[0].readinessProbes') && named.includes('spec.template.metadata.lables'),
  named.join(', '));

// Deployment invariants (deploy/README.md).
const pod = dep.spec.template.spec;
const c = pod.containers.find((x) => x.name === 'server');
const arg = (name) => {
  const i = c.args.indexOf(name);
  return i >= 0 ? c.args[i + 1] : undefined;
};
const drain = Number(arg('--drain-timeout-s'));
const preStop = Number(c.lifecycle?.preStop?.exec?.command?.[1] ?? c.lifecycle?.preStop?.sleep?.seconds);
check('no fixed replicas (the HPA owns the count)', dep.spec.replicas === undefined);
check('readiness probe on /readyz', c.readinessProbe?.httpGet?.path === '/readyz');
check('liveness probe on /healthz', c.livenessProbe?.httpGet?.path === '/healthz');
check('a startupProbe', !!c.startupProbe);
check('--drain-timeout-s set', Number.isFinite(drain) && drain > 0);
check('a preStop delay', Number.isFinite(preStop) && preStop > 0);
check(`terminationGracePeriodSeconds (${pod.terminationGracePeriodSeconds}) > preStop ${preStop} + drain ${drain}`,
  pod.terminationGracePeriodSeconds > preStop + drain);
check('runAsNonRoot', pod.securityContext?.runAsNonRoot === true && c.securityContext?.runAsNonRoot === true);
check('runAsUser is the image USER (10001)', pod.securityContext?.runAsUser === 10001);
check('readOnlyRootFilesystem', c.securityContext?.readOnlyRootFilesystem === true);
check('capabilities drop ALL', (c.securityContext?.capabilities?.drop || []).includes('ALL'));
check('no privilege escalation', c.securityContext?.allowPrivilegeEscalation === false);
check('RuntimeDefault seccomp', pod.securityContext?.seccompProfile?.type === 'RuntimeDefault');
check('GPU: runtimeClassName, toleration, nvidia.com/gpu limit',
  !!pod.runtimeClassName && (pod.tolerations || []).some((t) => t.key === 'nvidia.com/gpu') &&
  String(c.resources?.limits?.['nvidia.com/gpu']) === '1');
const env = (n) => (c.env || []).find((e) => e.name === n);
check('--threads from the CPU limit (downward API)',
  arg('--threads') === '$(CATGS_THREADS)' && env('CATGS_THREADS')?.valueFrom?.resourceFieldRef?.resource === 'limits.cpu');
check('the token from a Secret in CATGS_TOKEN, not on the command line (/proc)',
  arg('--token') === undefined && !(c.args || []).some((a) => a.includes('CATGS_TOKEN')) &&
  !!env('CATGS_TOKEN')?.valueFrom?.secretKeyRef);
const scenesVol = pod.volumes.find((v) => v.persistentVolumeClaim);
const pvc = objects.find((o) => o.kind === 'PersistentVolumeClaim' && o.metadata.name === scenesVol?.persistentVolumeClaim.claimName);
check('the scenes PVC is defined, ReadOnlyMany, mounted read-only',
  !!pvc && pvc.spec.accessModes.includes('ReadOnlyMany') && scenesVol.persistentVolumeClaim.readOnly === true &&
  c.volumeMounts.some((m) => m.name === scenesVol.name && m.readOnly));
const svc = byKind('Service');
check('no Service session affinity', (svc.spec.sessionAffinity || 'None') === 'None');
const ing = byKind('Ingress');
check('no Ingress cookie affinity',
  !Object.keys(ing.metadata.annotations || {}).some((k) => k.includes('affinity')));
check('Ingress: ingressClassName and TLS', !!ing.spec.ingressClassName && (ing.spec.tls || []).length > 0);
const pdb = byKind('PodDisruptionBudget');
check('a PodDisruptionBudget selecting the pods',
  !!pdb && JSON.stringify(pdb.spec.selector.matchLabels) === JSON.stringify(dep.spec.selector.matchLabels));
const hpa = byKind('HorizontalPodAutoscaler');
check('HPA scales this Deployment, with scale-down behaviour',
  hpa?.spec.scaleTargetRef.name === dep.metadata.name && !!hpa.spec.behavior?.scaleDown);
const sm = byKind('ServiceMonitor');
const smPort = sm?.spec.endpoints?.[0]?.port;
check('ServiceMonitor scrapes /metrics on a Service port',
  sm?.spec.endpoints?.[0]?.path === '/metrics' && svc.spec.ports.some((p) => p.name === smPort));
check('ServiceMonitor sends the token /metrics needs',
  sm?.spec.endpoints?.[0]?.authorization?.credentials?.name === env('CATGS_TOKEN')?.valueFrom?.secretKeyRef?.name);

// The HPA's pods metric exists: the adapter rule exposes it, and the server exports the gauge.
const adapter = parse(readFileSync(path.join(repo, 'deploy/k8s/prometheus-adapter-values.yaml'), 'utf8'));
const metric = hpa.spec.metrics[0].pods.metric.name;
const rule = (adapter.rules?.custom || []).find((r) => r.name?.as === metric);
check(`prometheus-adapter exposes the HPA metric ${metric}`, !!rule && rule.seriesQuery.startsWith(`${metric}{`));
const metricsSrc = readFileSync(path.join(repo, 'server/server_metrics.cpp'), 'utf8');
check(`the server exports ${metric}`, new RegExp(`\\b${metric}\\b`).test(metricsSrc));
const compose = parse(readFileSync(path.join(repo, 'deploy/compose.yaml'), 'utf8'));
check('compose.yaml parses', !!compose.services);

console.log(failures ? `${failures} failed` : 'all deploy checks passed');
process.exit(failures ? 1 : 0);
