// Validates deploy/k8s offline: every object against the Kubernetes OpenAPI schemas (kubernetes-
// models 4.5.1, Kubernetes 1.30+ API; the ServiceMonitor against the prometheus-operator CRD via
// @kubernetes-models/prometheus-operator), then the deployment's own invariants (readiness on
// /readyz, grace period = preStop + drain + margin, no fixed replicas, no affinity, ...), and
// that the HPA's metric is the one the prometheus-adapter rule exposes.
// The schema check covers types, formats (quantities, int32), enums and required fields; the
// compiled validators let unknown field names through, so a second walk (unknownFields) checks
// every field name against the models' TypeScript declarations (the interfaces the validators
// were generated from), as kubeconform -strict would (it is not packaged for Debian 12).
// Then what kustomization.yaml makes of them (its images: and configMapGenerator: applied as
// kustomize applies them; cross-checked against `kubectl kustomize` where kubectl is installed):
// every image a valid OCI reference naming its registry, the placeholder replaced; and that the
// pod can get its scene: every --scene path under a mounted volume that something fills.
// Each rule has a self-test that plants the fault it is for and expects it named.
// usage: node validate_k8s.mjs [REPO]. Exit 0 all pass, 1 a failure, 77 (SKIP) without npm ci.
import { execFileSync } from 'node:child_process';
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
check('fsGroupChangePolicy OnRootMismatch (no recursive chown of the volumes at every start)',
  pod.securityContext?.fsGroupChangePolicy === 'OnRootMismatch');
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

// ---- kustomization.yaml: images and the scene ConfigMap, as kustomize applies them ----------

// An OCI image reference (the grammar of github.com/distribution/reference): [domain/]path[:tag]
// [@digest], path components lowercase. Returns { name, domain, path, tag, digest } or { error }.
// The domain rule is Docker's: a first component without '.' or ':' that is not localhost and is
// lowercase belongs to the path (an image on Docker Hub).
const alnum = '[a-z0-9]+';
const pathComponent = `${alnum}(?:(?:[._]|__|-+)${alnum})*`;
const domainComponent = '(?:[a-zA-Z0-9]|[a-zA-Z0-9][a-zA-Z0-9-]*[a-zA-Z0-9])';
const domainRe = `(?:${domainComponent}(?:\\.${domainComponent})*|\\[[a-fA-F0-9:]+\\])(?::[0-9]+)?`;
const tagRe = '[\\w][\\w.-]{0,127}';
const digestRe = '[A-Za-z][A-Za-z0-9]*(?:[-_+.][A-Za-z][A-Za-z0-9]*)*:[0-9a-fA-F]{32,}';
const referenceRe = new RegExp(
  `^((?:(${domainRe})/)?(${pathComponent}(?:/${pathComponent})*))(?::(${tagRe}))?(?:@(${digestRe}))?$`);
function parseReference(ref) {
  if (typeof ref !== 'string') return { error: 'not a string' };
  const m = ref.match(referenceRe);
  if (!m) return { error: 'not an OCI reference ([registry/]path[:tag][@digest], path lowercase)' };
  let [, name, domain, rest, tag, digest] = m;
  if (name.length > 255) return { error: 'name longer than 255 characters' };
  if (domain && !/[.:]/.test(domain) && domain !== 'localhost' && domain === domain.toLowerCase()) {
    rest = name;
    domain = undefined;
  }
  const hexLength = { sha256: 64, sha384: 96, sha512: 128 }[digest?.split(':')[0]];
  if (digest && hexLength && digest.split(':')[1].length !== hexLength)
    return { error: `${digest.split(':')[0]} digest of ${digest.split(':')[1].length} hex digits, not ${hexLength}` };
  return { name, domain, path: rest, tag, digest };
}
// kustomize's split of an image value into name, tag and digest (api/image: the tag is what
// follows the last ':' after the last '/').
function splitImage(value) {
  let name = value;
  let digest = '';
  let tag = '';
  const at = name.indexOf('@');
  if (at >= 0) [name, digest] = [name.slice(0, at), name.slice(at + 1)];
  const colon = name.lastIndexOf(':');
  if (colon > name.lastIndexOf('/')) [name, tag] = [name.slice(0, colon), name.slice(colon + 1)];
  return { name, tag, digest };
}

// The pod specs of the workloads among `objs`, with where they are.
function podSpecs(objs) {
  const out = [];
  for (const o of objs) {
    const spec = o.kind === 'Pod' ? o.spec
      : o.kind === 'CronJob' ? o.spec?.jobTemplate?.spec?.template?.spec
      : ['Deployment', 'StatefulSet', 'DaemonSet', 'ReplicaSet', 'Job'].includes(o.kind) ? o.spec?.template?.spec
      : undefined;
    if (spec) out.push({ where: `${o.kind}/${o.metadata?.name}`, spec });
  }
  return out;
}
const allContainers = (spec) => [...(spec.initContainers || []), ...(spec.containers || [])];

const kustomizeFields = new Set(['apiVersion', 'kind', 'resources', 'images', 'configMapGenerator',
  'secretGenerator', 'generatorOptions', 'patches', 'namespace', 'namePrefix', 'nameSuffix', 'labels',
  'commonLabels', 'commonAnnotations', 'replicas', 'components']);
const imageFields = new Set(['name', 'newName', 'newTag', 'digest']);
const generatorFields = new Set(['name', 'namespace', 'behavior', 'literals', 'files', 'envs', 'options']);
// Problems of kustomization.yaml's own shape: known fields (a misspelt `image:` would be dropped
// silently by nothing; kustomize refuses unknown fields), resources present, well-formed entries.
function kustomizationProblems(k, dir) {
  const out = [];
  if (k?.kind !== 'Kustomization') out.push(`kind is ${k?.kind}, not Kustomization`);
  for (const f of Object.keys(k || {})) if (!kustomizeFields.has(f)) out.push(`unknown field ${f}`);
  for (const r of k?.resources || []) if (!existsSync(path.join(dir, r))) out.push(`resource ${r} missing`);
  for (const [i, e] of (k?.images || []).entries()) {
    for (const f of Object.keys(e)) if (!imageFields.has(f)) out.push(`images[${i}]: unknown field ${f}`);
    if (!e.name) out.push(`images[${i}]: no name`);
    if (e.newName !== undefined && (parseReference(e.newName).error || /[:@]/.test(e.newName.split('/').pop())))
      out.push(`images[${i}] (${e.name}): newName ${e.newName} is not an image name`);
    if (e.newTag !== undefined && !new RegExp(`^${tagRe}$`).test(String(e.newTag)))
      out.push(`images[${i}] (${e.name}): newTag ${JSON.stringify(e.newTag)} is not a tag`);
    if (e.digest !== undefined && (!new RegExp(`^${digestRe}$`).test(String(e.digest)) ||
        parseReference(`x@${e.digest}`).error))
      out.push(`images[${i}] (${e.name}): digest ${JSON.stringify(e.digest)} is not a digest (sha256:<64 hex>)`);
  }
  for (const [i, g] of (k?.configMapGenerator || []).entries())
    for (const f of Object.keys(g)) if (!generatorFields.has(f)) out.push(`configMapGenerator[${i}]: unknown field ${f}`);
  return out;
}

// `objs` as kustomize builds them with `k`: images: entries applied to every container's image
// (a match is the image's name without tag and digest; newName replaces the name, newTag and
// digest replace both tag and digest), configMapGenerator literals merged into (behavior merge)
// or replacing (replace) the data of the ConfigMap of that name. Also returns the entries that
// matched no image (a stale entry: the override silently does nothing).
function kustomize(objs, k) {
  const out = structuredClone(objs);
  const used = new Set();
  for (const { spec } of podSpecs(out)) {
    for (const ctr of allContainers(spec)) {
      const { name, tag, digest } = splitImage(ctr.image || '');
      const e = (k.images || []).find((x) => x.name === name);
      if (!e) continue;
      used.add(e.name);
      let [n, t, d] = [e.newName || name, tag, digest];
      if (e.newTag !== undefined || e.digest !== undefined) [t, d] = [e.newTag ?? '', e.digest ?? ''];
      ctr.image = `${n}${t !== '' ? `:${t}` : ''}${d ? `@${d}` : ''}`;
    }
  }
  for (const g of k.configMapGenerator || []) {
    const literals = Object.fromEntries((g.literals || []).map((l) => {
      const eq = l.indexOf('=');
      return [l.slice(0, eq), l.slice(eq + 1)];
    }));
    const cm = out.find((o) => o.kind === 'ConfigMap' && o.metadata.name === g.name);
    if (cm && g.behavior === 'replace') cm.data = literals;
    else if (cm && g.behavior === 'merge') cm.data = { ...cm.data, ...literals };
    else if (!cm) out.push({ apiVersion: 'v1', kind: 'ConfigMap', metadata: { name: g.name }, data: literals });
  }
  const stale = (k.images || []).filter((e) => !used.has(e.name)).map((e) => e.name);
  return { objects: out, stale };
}

// Image problems of the built objects: each container's image a valid reference, naming its
// registry (a host with '.' or ':', or localhost: not Docker Hub by default, not a placeholder
// like REGISTRY), with a tag or digest; and no images: entry that matches nothing.
function imageProblems(built, stale) {
  const out = stale.map((n) => `kustomization images: entry ${n} matches no container image`);
  for (const { where, spec } of podSpecs(built)) {
    for (const ctr of allContainers(spec)) {
      const r = parseReference(ctr.image);
      const at = `${where} ${ctr.name}: ${ctr.image}`;
      if (r.error) out.push(`${at}: ${r.error}`);
      else if (!r.domain || !(/[.:]/.test(r.domain) || r.domain === 'localhost'))
        out.push(`${at}: names no registry host (${r.domain ? `placeholder ${r.domain}` : 'Docker Hub implied'}): ` +
          'kustomization.yaml images: must replace it');
      else if (!r.tag && !r.digest) out.push(`${at}: neither tag nor digest (latest implied)`);
    }
  }
  return out;
}

// The value of $(VAR) references in `text`, from the container's env (a literal value, or a
// ConfigMap key among `objs`); unresolved ones stay as they are.
function expandVars(text, ctr, objs) {
  return text.replace(/\$\(([A-Za-z_][A-Za-z0-9_]*)\)/g, (all, v) => {
    const e = (ctr.env || []).find((x) => x.name === v);
    if (e?.value !== undefined) return e.value;
    const ref = e?.valueFrom?.configMapKeyRef;
    const cm = ref && objs.find((o) => o.kind === 'ConfigMap' && o.metadata.name === ref.name);
    return cm?.data?.[ref.key] ?? all;
  });
}
const under = (p, dir) => p === dir || p.startsWith(dir.endsWith('/') ? dir : `${dir}/`);

// Why a pod could not get its scene: for every --scene path of every (non-init) container, the
// longest volume mount that holds it, and what fills that volume: an emptyDir needs an init
// container of the same pod that mounts it writable and names its mount path in its command; a
// PersistentVolumeClaim needs the claim defined here with a writable access mode and a writer (a
// Job, or an init container, that mounts it writable); a ReadOnlyMany-only claim can never be
// filled through Kubernetes. Other volume types: no rule here knows how they are filled.
function sceneProblems(objs) {
  const out = [];
  const writers = (claim) => podSpecs(objs).flatMap(({ where, spec }) =>
    allContainers(spec).filter((ctr) => (ctr.volumeMounts || []).some((m) => {
      const v = (spec.volumes || []).find((x) => x.name === m.name);
      return v?.persistentVolumeClaim?.claimName === claim && !m.readOnly && !v.persistentVolumeClaim.readOnly;
    })).map((ctr) => `${where} ${ctr.name}`));
  for (const { where, spec } of podSpecs(objs)) {
    for (const ctr of spec.containers || []) {
      const args = [...(ctr.command || []), ...(ctr.args || [])];
      const scenes = [];
      args.forEach((a, i) => {
        if (a === '--scene' && i + 1 < args.length) scenes.push(args[i + 1]);
        else if (a.startsWith('--scene=')) scenes.push(a.slice('--scene='.length));
      });
      for (const raw of scenes) {
        const p = expandVars(raw, ctr, objs);
        const at = `${where} ${ctr.name} --scene ${raw}`;
        if (/\$\(/.test(p)) { out.push(`${at}: ${p} names a variable not set from a value or a ConfigMap here`); continue; }
        const mount = (ctr.volumeMounts || []).filter((m) => under(p, m.mountPath))
          .sort((a, b) => b.mountPath.length - a.mountPath.length)[0];
        if (!mount) { out.push(`${at}: not under any volume mount of the container`); continue; }
        const vol = (spec.volumes || []).find((v) => v.name === mount.name);
        if (!vol) { out.push(`${at}: mount ${mount.mountPath} names no volume ${mount.name}`); continue; }
        if (vol.emptyDir) {
          const fillers = (spec.initContainers || []).filter((ic) => (ic.volumeMounts || []).some((m) =>
            m.name === vol.name && !m.readOnly && [...(ic.command || []), ...(ic.args || [])].join(' ').includes(m.mountPath)));
          if (!fillers.length) out.push(`${at}: volume ${vol.name} is an emptyDir that no init container writes to`);
        } else if (vol.persistentVolumeClaim) {
          const name = vol.persistentVolumeClaim.claimName;
          const pvc = objs.find((o) => o.kind === 'PersistentVolumeClaim' && o.metadata.name === name);
          const modes = pvc?.spec?.accessModes || [];
          if (!pvc) out.push(`${at}: claim ${name} is not defined here, nothing shown to fill it`);
          else if (!modes.some((m) => m.startsWith('ReadWrite')))
            out.push(`${at}: claim ${name} is ${modes.join(', ')} only: no pod can write a scene into it`);
          else if (!writers(name).length) out.push(`${at}: claim ${name}: nothing here mounts it writable to fill it`);
        } else {
          const type = Object.keys(vol).filter((k) => k !== 'name').join(', ');
          out.push(`${at}: volume ${vol.name} (${type}): no rule knows what fills it`);
        }
      }
    }
  }
  return out;
}

// ConfigMap keys the containers read (env valueFrom, envFrom) that the manifests do not define
// (the pod would stay in CreateContainerConfigError), unless marked optional.
function configMapRefProblems(objs) {
  const out = [];
  const cm = (n) => objs.find((o) => o.kind === 'ConfigMap' && o.metadata.name === n);
  for (const { where, spec } of podSpecs(objs)) {
    for (const ctr of allContainers(spec)) {
      for (const e of ctr.env || []) {
        const ref = e.valueFrom?.configMapKeyRef;
        if (ref && !ref.optional && !(ref.key in (cm(ref.name)?.data || {})))
          out.push(`${where} ${ctr.name} env ${e.name}: ConfigMap ${ref.name} key ${ref.key} not defined`);
      }
      for (const e of ctr.envFrom || [])
        if (e.configMapRef && !e.configMapRef.optional && !cm(e.configMapRef.name))
          out.push(`${where} ${ctr.name} envFrom: ConfigMap ${e.configMapRef.name} not defined`);
    }
  }
  return out;
}

// Every container, init containers included: no privilege escalation, read-only root, drop ALL,
// non-root (its own or the pod's runAsNonRoot).
function hardeningProblems(objs) {
  const out = [];
  for (const { where, spec } of podSpecs(objs)) {
    for (const ctr of allContainers(spec)) {
      const sc = ctr.securityContext || {};
      const miss = [];
      if (sc.allowPrivilegeEscalation !== false) miss.push('allowPrivilegeEscalation: false');
      if (sc.readOnlyRootFilesystem !== true) miss.push('readOnlyRootFilesystem');
      if (!(sc.capabilities?.drop || []).includes('ALL')) miss.push('drop ALL');
      if ((sc.runAsNonRoot ?? spec.securityContext?.runAsNonRoot) !== true) miss.push('runAsNonRoot');
      if (miss.length) out.push(`${where} ${ctr.name}: no ${miss.join(', ')}`);
    }
  }
  return out;
}

const kdir = path.join(repo, 'deploy/k8s');
let kust = {};
try {
  kust = parse(readFileSync(path.join(kdir, 'kustomization.yaml'), 'utf8')) || {};
  check('kustomization.yaml parses', true);
} catch (e) {
  check('kustomization.yaml parses', false, e.message);
}
const kProblems = kustomizationProblems(kust, kdir);
check('kustomization.yaml: known fields, resources present, images: entries well formed', kProblems.length === 0,
  kProblems.join('; '));
check('kustomization.yaml builds catgs-stream.yaml', (kust.resources || []).includes('catgs-stream.yaml'));
const { objects: built, stale } = kustomize(objects, kust);
// The images the manifests name before kustomize: the placeholder is exactly an images: entry.
const placeholder = dep.spec.template.spec.containers.find((x) => x.name === 'server').image;
check(`the server image placeholder ${placeholder} is the name kustomization.yaml replaces`,
  (kust.images || []).some((e) => e.name === splitImage(placeholder).name && !!e.newName));
const imgProblems = imageProblems(built, stale);
check('every image, after kustomization.yaml, is an OCI reference naming its registry', imgProblems.length === 0,
  imgProblems.join('; '));
for (const { spec } of podSpecs(built))
  for (const ctr of allContainers(spec))
    if (!parseReference(ctr.image).digest)
      console.log(`note: ${ctr.name} runs ${ctr.image}, a tag: pin a digest in kustomization.yaml ` +
        'for rollouts that cannot drift');
// The emulation against kustomize itself, where kubectl (which embeds it) is installed.
let kubectlOut = null;
try {
  kubectlOut = execFileSync('kubectl', ['kustomize', kdir],
    { encoding: 'utf8', stdio: ['ignore', 'pipe', 'pipe'], timeout: 30000 });
} catch (e) {
  const why = e.code === 'ENOENT' ? 'kubectl not installed' : String(e.message).split('\n')[0];
  console.log(`note: kubectl kustomize not run (${why}): ` +
    'the images: and configMapGenerator: emulation is not cross-checked');
}
if (kubectlOut !== null) {
  const real = parseAllDocuments(kubectlOut).map((d) => d.toJS());
  const images = (objs) => podSpecs(objs)
    .flatMap(({ where, spec }) => allContainers(spec).map((x) => `${where} ${x.name}=${x.image}`)).sort();
  const cms = (objs) => objs.filter((o) => o.kind === 'ConfigMap')
    .map((o) => `${o.metadata.name}=${JSON.stringify(o.data, Object.keys(o.data || {}).sort())}`).sort();
  check('kubectl kustomize builds the same images and ConfigMaps as the emulation',
    JSON.stringify(images(real)) === JSON.stringify(images(built)) && JSON.stringify(cms(real)) === JSON.stringify(cms(built)),
    `kubectl: ${images(real).join(', ')} ${cms(real).join(', ')}; here: ${images(built).join(', ')} ${cms(built).join(', ')}`);
}

const sProblems = sceneProblems(built);
check('every --scene path lies under a mounted volume that something fills', sProblems.length === 0, sProblems.join('; '));
const server = podSpecs(built)[0].spec.containers.find((x) => x.name === 'server');
check('the server mounts its scenes read-only',
  (server.volumeMounts || []).some((m) => m.mountPath === '/scenes' && m.readOnly === true));
const cmProblems = configMapRefProblems(built);
check('every ConfigMap key the containers read is defined', cmProblems.length === 0, cmProblems.join('; '));
const hProblems = hardeningProblems(built);
check('every container, init containers too: non-root, read-only root, drop ALL, no escalation',
  hProblems.length === 0, hProblems.join('; '));
const fetcher = (built.find((o) => o.kind === 'Deployment').spec.template.spec.initContainers || [])
  .find((x) => x.name === 'fetch-scene');
const sceneUrl = fetcher && expandVars('$(SCENE_URL)', fetcher, built);
const sceneFile = fetcher && expandVars('$(SCENE_FILE)', fetcher, built);
let urlOk = false;
try {
  urlOk = ['http:', 'https:'].includes(new URL(sceneUrl).protocol);
} catch {
  // not a URL
}
check(`the scene URL (${sceneUrl}) is http(s), its file name (${sceneFile}) a scene format`,
  urlOk && /^[^/.][^/]*\.(ply|spz|splat|glb|sog)$/.test(sceneFile || ''));

// Self-tests of the rules above: each plants its fault and expects it named.
const names = (problems, ...needles) => needles.every((n) => problems.some((p) => p.includes(n)));
const good = ['registry.example.com/catgs/catgs-stream:cuda', `registry.example.com/catgs/catgs-stream@sha256:${'a'.repeat(64)}`,
  'localhost:5000/catgs-stream:cuda', 'docker.io/curlimages/curl:8.11.1', 'REGISTRY/catgs-stream:cuda'];
const bad = ['registry.example.com/Catgs/catgs-stream:cuda', 'registry.example.com/catgs-stream:cuda:1',
  'registry.example.com/catgs-stream:', 'registry.example.com/catgs-stream@sha256:abc',
  `registry.example.com/catgs-stream@sha256:${'a'.repeat(63)}`, 'registry.example.com/catgs-stream:-cuda',
  'registry.example.com//catgs-stream', 'https://registry.example.com/catgs-stream', 'catgs stream'];
const wrongGood = good.filter((r) => parseReference(r).error);
const wrongBad = bad.filter((r) => !parseReference(r).error);
check('the OCI reference parser accepts valid and refuses invalid references (self-test)',
  wrongGood.length === 0 && wrongBad.length === 0, `accepted ${wrongBad.join(', ')}; refused ${wrongGood.join(', ')}`);
{
  // No override: the placeholder registry stays (it parses: REGISTRY is a host name to the grammar).
  const k = structuredClone(kust);
  k.images = (k.images || []).filter((e) => e.name !== 'REGISTRY/catgs-stream');
  const b = kustomize(objects, k);
  const p = imageProblems(b.objects, b.stale);
  check('the image rule names the placeholder left without an override (self-test)',
    names(p, 'REGISTRY/catgs-stream:cuda: names no registry host (placeholder REGISTRY)'), p.join('; '));
  // The manifest's image renamed: the override matches nothing, and a Docker Hub name stays.
  const o = structuredClone(objects);
  podSpecs(o)[0].spec.containers[0].image = 'catgs-stream:cuda';
  const b2 = kustomize(o, kust);
  const p2 = imageProblems(b2.objects, b2.stale);
  check('the image rule names a stale images: entry and an image with no registry (self-test)',
    names(p2, 'entry REGISTRY/catgs-stream matches no container image',
      'catgs-stream:cuda: names no registry host (Docker Hub implied)'),
    p2.join('; '));
  // A malformed override: the reference kustomize would write does not parse.
  const k3 = structuredClone(kust);
  k3.images = [{ name: 'REGISTRY/catgs-stream', newName: 'registry.example.com/catgs-stream', newTag: 'cuda 13' },
    { name: 'docker.io/curlimages/curl', digest: 'sha256:1234' }];
  const b3 = kustomize(objects, k3);
  const p3 = [...kustomizationProblems(k3, kdir), ...imageProblems(b3.objects, b3.stale)];
  check('the image rules name a bad newTag and a short digest (self-test)',
    names(p3, 'newTag "cuda 13" is not a tag', 'digest "sha256:1234" is not a digest', 'catgs-stream:cuda 13'),
    p3.join('; '));
  const k4 = structuredClone(kust);
  k4.image = k4.images || [];
  delete k4.images;
  check('kustomization.yaml: a misspelt field is named (self-test)',
    names(kustomizationProblems(k4, kdir), 'unknown field image'));
}
{
  // The previous manifest's scenes: a ReadOnlyMany-only claim, mounted read-only, nothing fills it.
  const o = structuredClone(built);
  const spec = podSpecs(o)[0].spec;
  delete spec.initContainers;
  spec.volumes = spec.volumes.map((v) => (v.name !== 'scenes' ? v
    : { name: 'scenes', persistentVolumeClaim: { claimName: 'catgs-scenes', readOnly: true } }));
  o.push({ apiVersion: 'v1', kind: 'PersistentVolumeClaim', metadata: { name: 'catgs-scenes' },
    spec: { accessModes: ['ReadOnlyMany'] } });
  const p = sceneProblems(o);
  check('the scene rule names a ReadOnlyMany-only claim nothing can fill (self-test)',
    names(p, 'claim catgs-scenes is ReadOnlyMany only: no pod can write a scene into it'), p.join('; '));
  // A writable claim, but no Job or init container writes to it.
  o.find((x) => x.kind === 'PersistentVolumeClaim').spec.accessModes = ['ReadWriteMany', 'ReadOnlyMany'];
  const p2 = sceneProblems(o);
  check('the scene rule names a claim nothing mounts writable (self-test)',
    names(p2, 'claim catgs-scenes: nothing here mounts it writable'), p2.join('; '));
  // ... which a fill Job mounting it read-write satisfies.
  o.push({ apiVersion: 'batch/v1', kind: 'Job', metadata: { name: 'fill' }, spec: { template: { spec: {
    containers: [{ name: 'fill', image: 'x', volumeMounts: [{ name: 's', mountPath: '/s' }] }],
    volumes: [{ name: 's', persistentVolumeClaim: { claimName: 'catgs-scenes' } }] } } } });
  check('the scene rule accepts a ReadWriteMany claim that a Job fills (self-test)', sceneProblems(o).length === 0,
    sceneProblems(o).join('; '));
}
{
  // The emptyDir without its init container, and a --scene path outside every mount.
  const o = structuredClone(built);
  const spec = podSpecs(o)[0].spec;
  delete spec.initContainers;
  spec.containers[0].args.push('--scene', '/data/other.ply');
  const p = sceneProblems(o);
  check('the scene rule names an emptyDir nothing fills and a path outside the mounts (self-test)',
    names(p, '--scene /scenes: volume scenes is an emptyDir that no init container writes to',
      '--scene /data/other.ply: not under any volume mount'), p.join('; '));
}
{
  const o = structuredClone(built);
  delete o.find((x) => x.kind === 'ConfigMap' && x.metadata.name === 'catgs-stream-scene')?.data?.url;
  const p = configMapRefProblems(o);
  check('the ConfigMap rule names a missing key (self-test)',
    names(p, 'fetch-scene env SCENE_URL: ConfigMap catgs-stream-scene key url not defined'), p.join('; '));
  const o2 = structuredClone(built);
  delete podSpecs(o2)[0].spec.initContainers?.[0]?.securityContext?.allowPrivilegeEscalation;
  const p2 = hardeningProblems(o2);
  check('the hardening rule names an init container that may escalate (self-test)',
    names(p2, 'fetch-scene: no allowPrivilegeEscalation: false'), p2.join('; '));
}

// The HPA's pods metric exists: the adapter rule exposes it, and the server exports the gauge.
const adapter = parse(readFileSync(path.join(repo, 'deploy/k8s/prometheus-adapter-values.yaml'), 'utf8'));
const metric = hpa.spec.metrics[0].pods.metric.name;
const rule = (adapter.rules?.custom || []).find((r) => r.name?.as === metric);
check(`prometheus-adapter exposes the HPA metric ${metric}`, !!rule && rule.seriesQuery.startsWith(`${metric}{`));
const metricsSrc = readFileSync(path.join(repo, 'server/process/server_metrics.cpp'), 'utf8');
check(`the server exports ${metric}`, new RegExp(`\\b${metric}\\b`).test(metricsSrc));
const compose = parse(readFileSync(path.join(repo, 'deploy/compose.yaml'), 'utf8'));
check('compose.yaml parses', !!compose.services);

console.log(failures ? `${failures} failed` : 'all deploy checks passed');
process.exit(failures ? 1 : 0);
