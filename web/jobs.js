// Batch jobs in the viewer (issue 45): the server's jobs (GET /api/jobs), each with its state,
// progress bar, rate and time left, refreshed every two seconds while the "jobs" section is
// open. Submitting, fetching and cancelling stay with `crease job` and the Python package (they
// need the admin token, or write files). State for tests: `window.crease.jobs`.

const REFRESH_MS = 2000;

/** Seconds as a short duration: 42 s, 3 min 5 s, 1 h 12 min. */
export function duration(s) {
  if (!(s > 0)) return "";
  if (s < 60) return `${Math.round(s)} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${Math.round(s % 60)} s`;
  return `${Math.floor(s / 3600)} h ${Math.round((s % 3600) / 60)} min`;
}

/** One job's line: label, state, frames done of total, rate and time left or error. */
export function describeJob(j) {
  const label = j.name ? `${j.name} (${j.job})` : j.job;
  const parts = [`${label} · ${j.model} ${j.level}${j.encoding === "palette" ? " palette" : ""} · ${j.state}`, `${j.frames_done} / ${j.frames_total} frames`];
  if (j.state === "running" || j.state === "queued") {
    if (j.frames_per_second > 0) parts.push(`${j.frames_per_second.toFixed(0)} frames/s`);
    const left = duration(j.eta_seconds);
    if (left) parts.push(`${left} left`);
  }
  if (j.error) parts.push(j.error);
  return parts.join(" · ");
}

/** Fills `list` with the server's jobs once; `state.jobs` holds what was shown. */
export async function showJobs({ list, state }) {
  const r = await fetch("/api/jobs");
  if (!r.ok) {
    list.textContent = `jobs: ${(await r.text()).trim()}`;
    return;
  }
  const { jobs } = await r.json();
  state.jobs = jobs;
  if (!jobs.length) {
    list.textContent = "no jobs (crease job submit)";
    return;
  }
  list.replaceChildren(
    ...jobs.map((j) => {
      const row = document.createElement("div");
      row.className = "job";
      row.dataset.job = j.job;
      row.dataset.state = j.state;
      const bar = document.createElement("progress");
      bar.max = Math.max(1, j.frames_total);
      bar.value = j.frames_done;
      const text = document.createElement("div");
      text.textContent = describeJob(j);
      row.append(text, bar);
      return row;
    }),
  );
}

/**
 * Keeps `list` current while `details` is open (and once when it opens).
 * @param {{details: HTMLDetailsElement, list: HTMLElement, state: object, onError: (msg: string) => void}} o
 */
export function followJobs({ details, list, state, onError }) {
  let timer = null;
  const tick = async () => {
    try {
      await showJobs({ list, state });
    } catch (err) {
      onError(`jobs: ${err.message || err}`);
    }
    if (details.open) timer = setTimeout(tick, REFRESH_MS);
  };
  details.addEventListener("toggle", () => {
    clearTimeout(timer);
    if (details.open) tick();
  });
  if (details.open) tick();
}
