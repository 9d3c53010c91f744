// The submission form: a GLB scene, the job's JSON (checked against
// schemas/job.schema.json, embedded at build time, before it is sent) and
// whether to bake the impostors.
import Ajv2020 from "ajv/dist/2020.js";
import schema from "../../schemas/job.schema.json";
import { json } from "./api.js";
import { errorBox, h } from "./dom.js";

// The schema names Rust number formats (uint32, double, ...): not checked.
const ajv = new Ajv2020({ allErrors: true, strict: false, validateFormats: false });
const validateJob = ajv.compile(schema);

/// The schema's errors for `job` as lines, or [] when it is valid.
export function jobErrors(job) {
  if (validateJob(job)) return [];
  return validateJob.errors.map((e) => `${e.instancePath || "(the job)"} ${e.message}`);
}

/// A starting job: a view space to edit and the defaults of the main knobs.
function defaultJob() {
  const pick = (k) => schema.properties[k].default;
  return {
    view_space: { min: [0, 1.5, 0], max: [100, 2, 100] },
    target_frame_time_ms: pick("target_frame_time_ms"),
    max_error_px: pick("max_error_px"),
    camera: pick("camera"),
    cost_model: pick("cost_model"),
    memory: pick("memory"),
  };
}

export function submitPage(main) {
  const scene = h("input", { type: "file", id: "scene", accept: ".glb,model/gltf-binary" });
  const editor = h("textarea", { id: "job", spellcheck: "false" });
  editor.value = JSON.stringify(defaultJob(), null, 2);
  const bake = h("input", { type: "checkbox", id: "bake", checked: true });
  const out = h("div", { id: "submit-result" });
  const form = h(
    "form",
    { id: "submit-form" },
    h("div", {}, h("label", {}, "Scene (GLB) ", scene)),
    h("div", {}, h("label", { for: "job" }, "Job (JSON, ", h("code", {}, "schemas/job.schema.json"), ")"), h("br"), editor),
    h("div", {}, h("label", {}, bake, " bake the impostors (needed by the 3D viewer)")),
    h("div", {}, h("button", { type: "submit", id: "submit" }, "Submit")),
    out,
  );
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    out.replaceChildren();
    let job;
    try {
      job = JSON.parse(editor.value);
    } catch (e) {
      out.append(errorBox(`the job is not JSON: ${e.message}`));
      return;
    }
    const errors = jobErrors(job);
    if (errors.length) {
      out.append(errorBox(`the job does not match the job schema:\n${errors.join("\n")}`));
      return;
    }
    if (!scene.files.length) {
      out.append(errorBox("choose a scene file (GLB)"));
      return;
    }
    const body = new FormData();
    body.append("scene", scene.files[0]);
    body.append("job", new Blob([JSON.stringify(job)], { type: "application/json" }), "job.json");
    if (bake.checked) body.append("bake", "true");
    try {
      const accepted = await json("/v1/jobs", { method: "POST", body });
      location.hash = `#/jobs/${accepted.id}`;
    } catch (e) {
      out.append(errorBox(e));
    }
  });
  main.append(h("h1", {}, "Submit a job"), form);
}
