// Validates every object of a rendered manifest (kubectl kustomize output)
// against the Kubernetes API's JSON schemas bundled in the npm package
// kubernetes-models — offline, no cluster. Prints one line per object;
// exits 1 if any object is invalid or of a kind the package does not know.
//   node validate.mjs RENDERED.yaml
import { readFileSync } from "node:fs";
import { parseAllDocuments } from "yaml";

const docs = parseAllDocuments(readFileSync(process.argv[2], "utf8"))
  .map((d) => d.toJS())
  .filter((o) => o != null);
let bad = 0;
for (const obj of docs) {
  const name = `${obj.kind}/${obj.metadata?.name}`;
  const slash = obj.apiVersion.indexOf("/");
  const path = slash < 0 ? `${obj.apiVersion}` : `${obj.apiVersion.slice(0, slash)}/${obj.apiVersion.slice(slash + 1)}`;
  let Model;
  try {
    Model = (await import(`kubernetes-models/${path}/${obj.kind}`))[obj.kind];
  } catch (e) {
    bad++;
    console.log(`UNKNOWN ${obj.apiVersion} ${name}: ${e.message}`);
    continue;
  }
  try {
    new Model(obj).validate();
    console.log(`valid ${obj.apiVersion} ${name}`);
  } catch (e) {
    bad++;
    console.log(`INVALID ${obj.apiVersion} ${name}: ${e.message}`);
  }
}
console.log(`${docs.length - bad} of ${docs.length} objects valid`);
process.exit(bad ? 1 : 0);
