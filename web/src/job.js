// A job's page: its live state and progress (the job's server-sent events),
// then its summary, report, downloads and, for a baked job, the 3D viewer.
import { blobUrl, followEvents, json, request } from "./api.js";
import { errorBox, fmtTime, h } from "./dom.js";

const FINAL = new Set(["succeeded", "failed", "cancelled"]);

export async function jobPage(main, id, signal) {
  const root = h("section", { id: "job-page", "data-job": id });
  const state = h("span", { id: "job-state" });
  const stage = h("span", { id: "job-stage" });
  const bar = h("progress", { max: 1, value: 0 });
  const details = h("div", { id: "job-details" });
  root.append(
    h("h1", {}, "Job ", h("code", {}, id)),
    h("p", {}, "State: ", state, " ", stage, " ", bar),
    details,
  );
  main.append(root);

  const show = (s) => {
    root.dataset.state = s.state;
    state.textContent = s.state;
    state.className = s.state === "succeeded" ? "ok" : s.state === "failed" ? "error" : "";
    stage.textContent = s.stage ? `(${s.stage})` : "";
    bar.value = s.progress || 0;
  };

  let status;
  try {
    status = await json(`/v1/jobs/${id}`);
    show(status);
    if (!FINAL.has(status.state)) {
      try {
        await followEvents(id, show, signal);
      } catch (e) {
        if (signal.aborted) return;
        // The stream broke: poll every second instead.
        while (!FINAL.has(status.state) && !signal.aborted) {
          await new Promise((r) => setTimeout(r, 1000));
          status = await json(`/v1/jobs/${id}`);
          show(status);
        }
      }
      if (signal.aborted) return;
      status = await json(`/v1/jobs/${id}`);
      show(status);
    }
  } catch (e) {
    root.append(errorBox(e));
    return;
  }
  details.append(...finished(status));
  root.dataset.ready = "true";
}

function finished(s) {
  const out = [
    h("p", {}, `Submitted ${fmtTime(s.created_ms)}, started ${fmtTime(s.started_ms)}, ` +
      `finished ${fmtTime(s.finished_ms)}.`),
  ];
  if (s.error) out.push(errorBox(s.error));
  if (s.summary) out.push(h("h2", {}, "Summary"), summaryTable(s.summary));
  const files = [
    ["scene", "scene", false],
    ["job", "job.json", false],
  ];
  if (s.state === "succeeded") {
    files.push(["placement", "placement.json", true], ["evaluation", "evaluation.json", true],
      ["report", "report.html", true]);
    if (s.bake) files.push(["impostors.glb", "impostors.glb", true]);
  }
  out.push(h("h2", {}, "Downloads"), h("p", { class: "downloads" },
    files.map(([path, name]) => [download(s.id, path, name), " "])));
  if (s.state === "succeeded" && s.bake) {
    out.push(h("p", {}, h("a", { href: `#/jobs/${s.id}/view`, id: "open-viewer" }, "Open the 3D viewer")));
  } else if (s.state === "succeeded") {
    out.push(h("p", {}, "The 3D viewer needs baked impostors: submit the job with “bake”."));
  }
  if (s.state === "succeeded") out.push(h("h2", {}, "Report"), reportFrame(s.id));
  out.push(h("p", {}, h("button", { onclick: () => remove(s.id) }, "Delete the job")));
  return out;
}

function summaryTable(summary) {
  const rows = Object.entries(summary).map(([k, v]) =>
    h("tr", {}, h("th", {}, k), h("td", {}, typeof v === "object" ? JSON.stringify(v) : String(v))));
  return h("table", { id: "job-summary" }, rows);
}

/// A link fetching `/v1/jobs/{id}/{path}` with the token, then saving it.
function download(id, path, name) {
  return h("a", {
    href: "#",
    "data-file": path,
    onclick: async (ev) => {
      ev.preventDefault();
      try {
        const url = await blobUrl(`/v1/jobs/${id}/${path}`);
        const a = h("a", { href: url, download: `${id}-${name}` });
        document.body.append(a);
        a.click();
        a.remove();
        setTimeout(() => URL.revokeObjectURL(url), 60_000);
      } catch (e) {
        ev.target.after(errorBox(e));
      }
    },
  }, name);
}

function reportFrame(id) {
  const frame = h("iframe", { class: "report", title: "report", sandbox: "allow-scripts" });
  blobUrl(`/v1/jobs/${id}/report`).then(
    (url) => { frame.src = url; },
    (e) => frame.replaceWith(errorBox(e)),
  );
  return frame;
}

async function remove(id) {
  if (!confirm(`Delete job ${id} and its results?`)) return;
  await request(`/v1/jobs/${id}`, { method: "DELETE" });
  location.hash = "#/";
}
