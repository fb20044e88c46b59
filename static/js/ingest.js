// Uploads videos one by one with a byte progress bar (XHR: fetch has no upload progress),
// then follows each ingest job's progress until it finishes, saying when a video copies one
// already in the workspace. What tells two files of one name apart: under the name, the file's
// size and upload time; once ingested, the video it became beside its frame count.
import { api, el, poll } from "./api.js";
import { keyboardHelp } from "./help.js";
import { summary } from "./job_summary.js";
import { plural } from "./labels.js";
import { failure, HEADERS } from "./request.js";
import { sessionEnded } from "./session_ended.js";

const form = document.getElementById("upload");
const list = document.getElementById("uploads");

function upload(file, fields, onProgress) {
  return new Promise((resolve, reject) => {
    const body = new FormData();
    body.append("file", file);
    for (const [key, value] of fields) body.append(key, value);
    const xhr = new XMLHttpRequest();
    xhr.open("POST", form.dataset.src);
    for (const [name, value] of Object.entries(HEADERS)) xhr.setRequestHeader(name, value);
    xhr.upload.onprogress = (e) => e.lengthComputable && onProgress(e.loaded / e.total);
    xhr.onload = () => {
      const data = JSON.parse(xhr.responseText || "{}");
      xhr.status < 300 ? resolve(data) : reject(failure(xhr.status, data, xhr.statusText));
    };
    xhr.onerror = () => reject(new Error("network error during upload"));
    xhr.send(body);
  });
}

// "12.3 MiB", as the server words sizes (webapp.bodies.size_text).
function sizeText(bytes) {
  if (bytes < 1024) return plural(bytes, "byte");
  const [value, unit] = bytes < 2 ** 20 ? [bytes / 1024, "KiB"] : [bytes / 2 ** 20, "MiB"];
  return `${Number(value.toPrecision(3))} ${unit}`;
}

// "14:05:31", in the browser's time.
const clockTime = (date) => date.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit", second: "2-digit" });

// "12.3 MiB · 14:05:31": the file's size and when its upload began.
const fileFacts = (file, started) => `${sizeText(file.size)} · ${clockTime(started)}`;

// A job's progress and outcome in its row; whether it has ended.
function showJob(current, row) {
  const label = row.querySelector(".status");
  row.querySelector("progress").value = current.progress;
  const done = ["succeeded", "failed", "interrupted"].includes(current.state);
  label.replaceChildren(el("a", { href: `${form.dataset.jobPage}${current.id}` }, `ingest job #${current.id}`),
                        `: ${current.state}${done ? ` — ${summary(current)}` : ""}`);
  const copy = current.result?.copy_of;
  if (copy) {
    label.append(el("span", { className: "copy-note" },
      `Looks like a copy of video ${copy.video_id} (“${copy.video_name}”; ${copy.matched} of ${copy.frames} frames `
      + "alike): kept in the same scene group, so no split puts them on different sides."));
  }
  if (done) {
    row.classList.toggle("failed", current.state !== "succeeded");
    const videoId = current.result?.video_id;
    // (a skipped upload's summary names the video it already is)
    if (current.state === "succeeded" && videoId != null && !current.result.skipped) {
      label.append(" · ", el("a", { href: `/review?video_id=${videoId}` }, `video #${videoId}`));
    }
  }
  return done;
}

function follow(job, row) {
  const stop = poll(async () => {
    if (showJob(await api(`${form.dataset.jobs}/${job.id}`), row)) stop();
  }, 1000);
}

// One file's row. The facts come last: the row's grid puts them on a line of their own, under the name.
function uploadRow(name, status, facts) {
  return el("li", {}, el("span", { className: "name", title: name }, name), el("progress", { max: 1, value: 0 }),
            el("span", { className: "status" }, status), el("span", { className: "file-facts muted" }, facts));
}

// A reload keeps the list: this curator's latest ingest jobs come back as rows, those still running followed.
async function restoreRows() {
  const { items } = await api(`${form.dataset.jobs}?kind=ingest&mine=1&limit=${RESTORED_ROWS}`);
  for (const job of items) {
    const row = uploadRow(job.params?.original_name ?? `ingest job #${job.id}`, "",
                          `uploaded ${clockTime(new Date(job.created_at))}`);
    list.append(row);
    if (!showJob(job, row)) follow(job, row);
  }
}

const RESTORED_ROWS = 20;
const button = form.querySelector("button[type=submit]");

form.addEventListener("submit", async (event) => {
  event.preventDefault();
  if (button.disabled) return;  // a double click sends the files once
  button.disabled = true;
  button.textContent = "Uploading…";
  try {
    await uploadAll();
  } finally {
    button.disabled = false;
    button.textContent = "Upload and ingest";
    form.reset();
  }
});

async function uploadAll() {
  const files = [...form.elements.file.files];
  // The disparities are one video's, sent with it (they are in `fields`, as the form's "mono" entries).
  if (form.elements.mono.files.length && files.length > 1) {
    list.prepend(el("li", { className: "failed" }, el("span", { className: "status" },
      `Not uploaded: the monocular disparities are one video's, but ${files.length} videos are chosen.`)));
    return;
  }
  // An unchecked box sends nothing, and the API's default is to prefilter: always say it explicitly.
  const fields = [...new FormData(form)].filter(([key]) => !["file", "prefilter"].includes(key));
  fields.push(["prefilter", form.elements.prefilter.checked ? "1" : "0"]);
  for (const file of files) {
    const row = uploadRow(file.name, "uploading…", fileFacts(file, new Date()));
    list.prepend(row);
    if (file.size > Number(form.dataset.maxBytes)) {
      row.querySelector(".status").textContent = "too large for this server's upload limit";
      row.classList.add("failed");
      continue;
    }
    try {
      const job = await upload(file, fields, (f) => { row.querySelector("progress").value = f; });
      row.querySelector("progress").value = 0;
      if (job.sample_blocker) {
        row.append(el("span", { className: "sample-blocker" }, `No samples from this video: ${job.sample_blocker}`));
      }
      follow(job, row);
    } catch (err) {
      row.querySelector(".status").textContent = sessionEnded(err) ? "not uploaded" : err.message;
      row.classList.add("failed");
    }
  }
}

restoreRows().catch(() => {});  // a list that cannot be fetched leaves the form as it is

keyboardHelp([
  ["`Enter` in a field", "upload and ingest the chosen files"],
  ["Video files", "choose several at once: they upload one after another, each becoming an ingest job"],
  ["Frames per second", "how many frames are kept per second of video (2, the paper's rate); near-duplicate "
                        + "frames are dropped as well"],
  ["Source", "where the videos come from (web, generated, real capture)"],
  ["Illusion types", "what the videos show, kept with each video"],
  ["Run the VLM prefilter", "ask the prefilter about every new frame, so curators review only what it keeps"],
  ["A copy", "a video whose frames match one already here (re-encoded, resized or renamed) joins that video's "
             + "scene group: training and export splits keep the two on one side"],
], { note: "Each row below links to its job, whose page shows the full log, and once ingested to the video "
           + "it became. Under each file's name: its size and when its upload began." });
