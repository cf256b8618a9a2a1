// Validates deploy/k8s against the Kubernetes API's own JSON schemas
// (kubernetes-models, which validates with ajv), since no cluster runs here:
// every document of every manifest must be a known kind that its schema
// accepts, and the kustomization must list exactly the manifests there.
// Also checks what the schemas cannot: probes name ports the container
// declares, Services select pods their Deployments label, and the HPA scales
// a Deployment that exists.
//
//   node tests/deploy/validate_manifests.mjs deploy/k8s
import fs from "node:fs";
import path from "node:path";

// The npm packages (scripts/install-deps.sh runs npm ci here): without them
// the test skips (77), and fails under CI=true.
let YAML;
try {
  YAML = (await import("yaml")).default;
  await import("kubernetes-models/apps/v1");
} catch (e) {
  const why = `the npm packages of tests/deploy are missing (scripts/install-deps.sh installs them): ${e.message}`;
  console.error(why);
  process.exit(process.env.CI === "true" ? 1 : 77);
}

const dir = process.argv[2];
if (!dir) {
  console.error("usage: validate_manifests.mjs DEPLOY_DIR");
  process.exit(2);
}
const problems = [];

// The validator must be able to fail: a Deployment with a wrong type is refused.
{
  const { Deployment } = await import("kubernetes-models/apps/v1");
  let refused = false;
  try {
    new Deployment({ apiVersion: "apps/v1", kind: "Deployment", metadata: { name: "x" }, spec: { replicas: "two" } })
      .validate();
  } catch (e) {
    refused = true;
  }
  if (!refused) {
    console.error("the schema validator accepted a Deployment with replicas: \"two\"");
    process.exit(1);
  }
}
const objects = [];
const files = fs.readdirSync(dir).filter((f) => f.endsWith(".yaml")).sort();
for (const file of files) {
  const docs = YAML.parseAllDocuments(fs.readFileSync(path.join(dir, file), "utf8"));
  for (const [i, doc] of docs.entries()) {
    const where = `${file}, document ${i + 1}`;
    if (doc.errors.length) {
      problems.push(`${where}: ${doc.errors[0].message}`);
      continue;
    }
    const obj = doc.toJS();
    if (obj === null) continue;
    if (file === "kustomization.yaml") {
      const listed = [...(obj.resources ?? [])].sort();
      const manifests = files.filter((f) => f !== "kustomization.yaml");
      if (JSON.stringify(listed) !== JSON.stringify(manifests)) {
        problems.push(`${where}: resources ${JSON.stringify(listed)} are not the manifests ${JSON.stringify(manifests)}`);
      }
      continue;
    }
    const { apiVersion, kind } = obj;
    const group = apiVersion?.includes("/") ? apiVersion : `${apiVersion}`;
    let Model;
    try {
      Model = (await import(`kubernetes-models/${group}`))[kind];
    } catch (e) {
      Model = undefined;
    }
    if (!Model) {
      problems.push(`${where}: no schema for ${apiVersion} ${kind}`);
      continue;
    }
    try {
      new Model(obj).validate();
      objects.push({ where, obj });
      console.log(`${where}: ${apiVersion} ${kind} ${obj.metadata?.name}: valid`);
    } catch (e) {
      problems.push(`${where}: ${apiVersion} ${kind} ${obj.metadata?.name}: ${e.message}`);
    }
  }
}

// What the schemas cannot see.
const byKind = (k) => objects.filter((o) => o.obj.kind === k).map((o) => o.obj);
const workloads = [...byKind("Deployment"), ...byKind("StatefulSet")];
for (const w of workloads) {
  for (const c of w.spec.template.spec.containers) {
    const ports = new Set((c.ports ?? []).flatMap((p) => [p.name, p.containerPort]));
    for (const probe of ["readinessProbe", "livenessProbe", "startupProbe"]) {
      const p = c[probe];
      const port = p?.httpGet?.port ?? p?.tcpSocket?.port;
      if (p && !ports.has(port)) problems.push(`${w.kind} ${w.metadata.name}: ${probe} port ${port} is not declared`);
    }
  }
}
for (const s of byKind("Service")) {
  const selected = workloads.filter((w) =>
    Object.entries(s.spec.selector ?? {}).every(([k, v]) => w.spec.template.metadata.labels?.[k] === v));
  if (selected.length === 0) problems.push(`Service ${s.metadata.name}: selects no workload's pods`);
  for (const p of s.spec.ports) {
    const named = selected.some((w) =>
      w.spec.template.spec.containers.some((c) => (c.ports ?? []).some((cp) => cp.name === p.targetPort || cp.containerPort === p.targetPort)));
    if (!named) problems.push(`Service ${s.metadata.name}: targetPort ${p.targetPort} is no container's port`);
  }
}
// The relay is authenticated both ways (docs/deployment.md): NATS requires
// a user, and gmr-server gives its credentials and the relay secret, from
// files the pod mounts.
for (const d of byKind("Deployment").filter((w) => w.metadata.name === "gmr-server")) {
  const c = d.spec.template.spec.containers[0];
  const args = c.args ?? [];
  const mounted = (file) => (c.volumeMounts ?? []).some((m) => file.startsWith(m.mountPath + "/"));
  for (const flag of ["--nats-creds", "--relay-secret-file"]) {
    const i = args.indexOf(flag);
    if (i < 0) problems.push(`Deployment gmr-server: no ${flag} in its args`);
    else if (!mounted(args[i + 1])) problems.push(`Deployment gmr-server: ${flag} ${args[i + 1]} is on no mounted volume`);
  }
}
{
  const conf = byKind("ConfigMap").find((m) => m.metadata.name === "gmr-nats-config")?.data?.["nats.conf"] ?? "";
  if (!/authorization\s*{[^}]*\busers\s*=/s.test(conf)) problems.push("ConfigMap gmr-nats-config: nats.conf has no authorization users");
  const nats = byKind("StatefulSet").find((s) => s.metadata.name === "gmr-nats");
  const args = nats?.spec.template.spec.containers[0].args ?? [];
  if (args.join(" ") !== "-c /etc/nats/nats.conf") problems.push("StatefulSet gmr-nats: does not run nats.conf");
}
for (const h of byKind("HorizontalPodAutoscaler")) {
  const ref = h.spec.scaleTargetRef;
  if (!workloads.some((w) => w.kind === ref.kind && w.metadata.name === ref.name)) {
    problems.push(`HorizontalPodAutoscaler ${h.metadata.name}: scales ${ref.kind} ${ref.name}, which is not here`);
  }
}

if (problems.length) {
  console.error(problems.join("\n"));
  process.exit(1);
}
console.log(`${objects.length} objects in ${files.length} files: valid`);
