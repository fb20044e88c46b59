// One frame held by this annotator: its lease kept alive while the page is open, drafts saved a moment
// after each change, and the submit. Saves go one at a time, each carrying the version the previous
// one returned, so the server's stale-version check only ever fires for someone else's save.
import { call } from "../request.js";
import { toServer } from "./state.js";

const SAVE_DELAY_MS = 2000;
const RETRY_MS = 5000;

export class FrameSession {
  // hooks: saving(), saved(doc, version), conflict(message), failed(error), leaseKept(renewal: the
  // lease answer), leaseLost(message)
  constructor(api, frame, saved, hooks) {
    this.url = `${api}/frames/${frame.id}`;
    this.frame = frame;
    this.version = frame.annotation_version;
    this.saved = saved;     // the document the server holds
    this.pending = null;    // the document waiting to be saved
    this.hooks = hooks;
    this.chain = Promise.resolve();
    this.closed = false;
  }

  keepLease(leaseS) {
    this.leaseTimer = setInterval(async () => {
      const res = await call(`${this.url}/lease`);
      if (res.ok) this.hooks.leaseKept(res.data);
      if (res.status === 409) {
        this.close();
        this.hooks.leaseLost(res.error.message);
      }
    }, leaseS * 1000 / 3);
  }

  schedule(doc) {
    this.pending = doc;
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.flush(), SAVE_DELAY_MS);
  }

  cancel() {
    clearTimeout(this.timer);
    this.pending = null;
  }

  flush() {
    clearTimeout(this.timer);
    this.chain = this.chain.then(() => this.write());
    return this.chain;
  }

  async write() {
    const doc = this.pending;
    if (!doc || doc === this.saved || this.closed || this.conflicted) return;
    this.pending = null;
    this.hooks.saving();
    const res = await this.send(doc, false);
    if (res.ok) return this.hooks.saved(doc, this.version);
    if (res.status === 409) {
      this.conflicted = true;
      return this.hooks.conflict(res.error.message);
    }
    this.pending ??= doc;
    this.timer = setTimeout(() => this.flush(), RETRY_MS);
    this.hooks.failed(res.error);
  }

  async send(doc, submit) {
    const { height, width } = this.frame;
    const res = await call(`${this.url}/annotation`, {
      body: { version: this.version, regions: toServer(doc, height, width), submit },
    });
    if (res.ok) {
      this.version = res.data.annotation_version;
      this.saved = doc;
    }
    return res;
  }

  // Waits for a save in flight, so the submit carries the version that save returned.
  async submit(doc) {
    this.cancel();
    await this.chain;
    const res = await this.send(doc, true);
    if (res.ok) this.close();
    return res;
  }

  // keepalive: the request outlives the page when the tab closes or reloads.
  release() {
    this.close();
    return call(`${this.url}/lease/release`, { keepalive: true });
  }

  close() {
    this.closed = true;
    clearInterval(this.leaseTimer);
    clearTimeout(this.timer);
  }
}
