// Keeps the funnel counts live as frames move through the pipeline; `?` says what each count means.
import { api, poll } from "./api.js";
import { keyboardHelp } from "./help.js";

const funnel = document.getElementById("funnel");

poll(async () => {
  const counts = await api(funnel.dataset.src);
  const top = counts.frames || 1;
  for (const item of funnel.querySelectorAll("li[data-stage]")) {
    const stage = item.dataset.stage;
    item.querySelector(".count").textContent = counts[stage];
    item.querySelector(".bar")?.style.setProperty("--w", `${(100 * counts[stage] / top).toFixed(1)}%`);
  }
}, 5000);

// No keys of its own: the help reads the counts (each row's title says it too, on hover).
keyboardHelp([
  ...[...funnel.querySelectorAll("li[data-stage]")].map((item) => [item.dataset.stage, item.title]),
], { note: "The counts follow the pipeline live (every 5 s). A frame counts at every stage it has reached, "
          + "so each bar is at most the one above it." });
