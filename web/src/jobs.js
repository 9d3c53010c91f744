// The job list: every job the token may see, newest first.
import { json } from "./api.js";
import { errorBox, fmtTime, h } from "./dom.js";

export async function jobsPage(main) {
  main.append(h("h1", {}, "Jobs"), h("p", {}, h("a", { href: "#/submit" }, "Submit a job")));
  const jobs = [];
  try {
    let after = null;
    do {
      const q = after ? `?limit=500&after=${encodeURIComponent(after)}` : "?limit=500";
      const page = await json(`/v1/jobs${q}`);
      jobs.push(...page.jobs);
      after = page.next_after;
    } while (after);
  } catch (e) {
    main.append(errorBox(e));
    return;
  }
  if (!jobs.length) {
    main.append(h("p", {}, "No jobs yet."));
    return;
  }
  jobs.reverse();
  main.append(
    h(
      "table",
      { id: "jobs" },
      h("tr", {}, h("th", {}, "job"), h("th", {}, "state"), h("th", {}, "stage"),
        h("th", {}, "progress"), h("th", {}, "submitted")),
      jobs.map((j) =>
        h("tr", {},
          h("td", {}, h("a", { href: `#/jobs/${j.id}` }, j.id)),
          h("td", {}, j.state),
          h("td", {}, j.stage || ""),
          h("td", {}, `${Math.round(100 * (j.progress || 0))} %`),
          h("td", {}, fmtTime(j.created_ms)),
        ),
      ),
    ),
  );
}
