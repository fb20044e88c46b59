// Keeps the funnel counts live as frames move through the pipeline.
import { api, poll } from "./api.js";

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
