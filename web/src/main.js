// The page's router: #/ (jobs), #/submit, #/jobs/ID, #/jobs/ID/view
// (?triangles=N: the display budget for the scene's triangles, 0 for none).
import "./style.css";
import { setToken, token } from "./api.js";
import { jobPage } from "./job.js";
import { jobsPage } from "./jobs.js";
import { submitPage } from "./submit.js";
import { viewerPage } from "./viewer.js";

let current = null;

function route() {
  if (current) current.abort();
  current = new AbortController();
  const main = document.getElementById("main");
  main.replaceChildren();
  const hash = location.hash.replace(/^#/, "") || "/";
  let m;
  if (hash === "/submit") submitPage(main);
  else if ((m = hash.match(/^\/jobs\/([\w-]+)\/view(?:\?triangles=(\d+))?$/))) {
    viewerPage(main, m[1], current.signal, m[2] === undefined ? undefined : Number(m[2]));
  }
  else if ((m = hash.match(/^\/jobs\/([\w-]+)$/))) jobPage(main, m[1], current.signal);
  else jobsPage(main);
}

const input = document.getElementById("token");
input.value = token();
input.addEventListener("change", () => {
  setToken(input.value.trim());
  route();
});
window.addEventListener("hashchange", route);
route();
