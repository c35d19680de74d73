// Takes in the viewer (issue 22): the room's recorded takes (GET /api/takes?room=ID), each with a
// download of its skinned glTF animation (GET /api/takes/{id}/glb) and "play", which opens a
// private replay room for it (POST /api/takes/{id}/replay) and reloads the viewer on that room
// with its publish token (`?room=replay-…&take=ID#token=…`). On such a page the player fetches
// the take's frames (GET /api/takes/{id}/frames: JSON control frames and their times) and
// publishes them into the room at their recorded timing through the viewer's socket: a timeline
// to scrub, pause and play, and a speed. State for tests: `window.crease.take`.

const SPEEDS = [0.25, 0.5, 1, 2, 4];

/** Seconds as m:ss.s. */
function clock(s) {
  const m = Math.floor(s / 60);
  return `${m}:${(s - 60 * m).toFixed(1).padStart(4, "0")}`;
}

/** The index of the last frame at or before `t` seconds (binary search on `times`). */
export function frameAt(times, t) {
  let lo = 0;
  let hi = times.length - 1;
  if (t <= times[0]) return 0;
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (times[mid] <= t) lo = mid;
    else hi = mid - 1;
  }
  return lo;
}

/**
 * Fills `list` with room `roomId`'s takes; `state.take.list` holds their ids.
 * @param {{roomId: string, list: HTMLElement, state: object, onError: (msg: string) => void}} o
 */
export async function listTakes({ roomId, list, state, onError }) {
  const r = await fetch(`/api/takes?room=${encodeURIComponent(roomId)}`);
  if (!r.ok) {
    list.textContent = r.status === 409 ? "this server records no takes" : `takes: ${(await r.text()).trim()}`;
    return;
  }
  const { takes } = await r.json();
  state.take.list = takes.map((t) => t.take);
  if (!takes.length) {
    list.textContent = "no takes of this room yet (crease take start)";
    return;
  }
  list.replaceChildren(
    ...takes.map((t) => {
      const row = document.createElement("div");
      row.className = "take";
      row.dataset.take = t.take;
      const label = document.createElement("span");
      label.textContent = `${t.name || t.take.split("-").slice(-2).join("-")} · ${clock(t.duration_s)} · ${t.frames} frames${t.recording ? " · recording" : ""}${t.truncated ? " · truncated" : ""}`;
      label.title = t.take;
      const play = document.createElement("button");
      play.type = "button";
      play.textContent = "play";
      play.disabled = t.frames === 0;
      play.addEventListener("click", async () => {
        const res = await fetch(`/api/takes/${encodeURIComponent(t.take)}/replay`, { method: "POST" });
        if (!res.ok) return onError(`replay: ${(await res.text()).trim()}`);
        const room = await res.json();
        const q = new URLSearchParams(location.search);
        q.set("room", room.room);
        q.set("take", t.take);
        location.assign(`${location.pathname}?${q}#token=${encodeURIComponent(room.publish_token)}`);
      });
      const glb = document.createElement("a");
      glb.href = `/api/takes/${encodeURIComponent(t.take)}/glb`;
      glb.textContent = "glTF";
      glb.download = `${t.take}.glb`;
      row.append(label, " ", play, " ", glb);
      return row;
    }),
  );
}

/**
 * The player of take `takeId` in its replay room: publishes frames with `send(jsonFrame)`.
 * @param {{takeId: string, root: HTMLElement, state: object, send: (frame: object) => boolean,
 *   onError: (msg: string) => void}} o
 */
export async function startPlayer({ takeId, root, state, send, onError }) {
  const r = await fetch(`/api/takes/${encodeURIComponent(takeId)}/frames`);
  if (!r.ok) return onError(`take ${takeId}: ${(await r.text()).trim()}`);
  const take = await r.json();
  const { times, frames } = take;
  const end = times[times.length - 1];
  const p = state.take;
  Object.assign(p, { id: takeId, frames: frames.length, duration: end, index: -1, t: 0, playing: true, speed: 1, sent: 0, loaded: true });

  const playButton = document.createElement("button");
  playButton.type = "button";
  const scrub = document.createElement("input");
  scrub.type = "range";
  scrub.min = "0";
  scrub.max = String(frames.length - 1);
  scrub.value = "0";
  scrub.id = "take-scrub";
  const speed = document.createElement("select");
  speed.id = "take-speed";
  for (const s of SPEEDS) speed.append(new Option(`${s}×`, String(s), false, s === 1));
  const time = document.createElement("span");
  time.className = "take-time";
  const title = document.createElement("div");
  title.textContent = `take ${takeId} (from room ${take.room})`;
  const controls = document.createElement("div");
  controls.append(playButton, " ", speed, " ", time);
  root.replaceChildren(title, scrub, controls);
  root.hidden = false;

  const show = () => {
    playButton.textContent = p.playing ? "pause" : "play";
    time.textContent = `${clock(p.t)} / ${clock(end)}`;
    scrub.value = String(Math.max(p.index, 0));
  };
  /** Sends frame i unless it is the one shown; keeps `p` in step. */
  const goTo = (i) => {
    if (i === p.index) return;
    if (send(frames[i])) {
      p.index = i;
      p.sent += 1;
    }
  };
  playButton.addEventListener("click", () => {
    if (!p.playing && p.index >= frames.length - 1) p.t = 0; // play again from the start
    p.playing = !p.playing;
    show();
  });
  speed.addEventListener("change", () => {
    p.speed = Number(speed.value);
  });
  scrub.addEventListener("input", () => {
    p.playing = false;
    const i = Number(scrub.value);
    p.t = times[i];
    goTo(i);
    show();
  });

  let last = performance.now();
  const tick = (now) => {
    const dt = (now - last) / 1000;
    last = now;
    if (p.playing) {
      p.t = Math.min(p.t + dt * p.speed, end);
      goTo(frameAt(times, p.t));
      if (p.t >= end && p.index === frames.length - 1) p.playing = false;
    }
    show();
    requestAnimationFrame(tick);
  };
  show();
  requestAnimationFrame(tick);
}
