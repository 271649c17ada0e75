#!/usr/bin/env python3
"""Issue 17 item 3: what a large floor plan costs the service (docs/security.md).

Starts `planner-service serve` on a fresh data directory, uploads a 20000 x 5000 PNG (walls
every 5 m, about 100 KB), and reports the upload's time, the service's peak memory (VmHWM), the
database growth, the first and the second `GET /maps/{name}/image`, and three concurrent
previews of the same picture. Usage: scripts/measure-map-images.py [BIN_DIR]
"""
import io, json, os, re, subprocess, sys, tempfile, threading, time, urllib.request

from PIL import Image, ImageDraw

BIN = sys.argv[1] if len(sys.argv) > 1 else "target/debug"
TOKEN = "measure-token-0123456789abcdef"


def plan_png(w=20000, h=5000):
    img = Image.new("L", (w, h), 254)
    d = ImageDraw.Draw(img)
    for x in range(0, w, 100):
        d.rectangle([x, 0, x + 3, h - 1], fill=0)
    for y in range(0, h, 100):
        d.rectangle([0, y, w - 1, y + 3], fill=0)
    buf = io.BytesIO()
    img.save(buf, "PNG", optimize=True)
    return buf.getvalue()


def multipart(fields, files):
    b = "----measure"
    out = io.BytesIO()
    for k, v in fields.items():
        out.write(f"--{b}\r\nContent-Disposition: form-data; name=\"{k}\"\r\n\r\n{v}\r\n".encode())
    for k, (fname, data) in files.items():
        out.write(f"--{b}\r\nContent-Disposition: form-data; name=\"{k}\"; filename=\"{fname}\"\r\nContent-Type: image/png\r\n\r\n".encode())
        out.write(data)
        out.write(b"\r\n")
    out.write(f"--{b}--\r\n".encode())
    return out.getvalue(), f"multipart/form-data; boundary={b}"


def hwm_mb(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmHWM"):
                return int(line.split()[1]) / 1024
    return float("nan")


def reset_hwm(pid):
    # Writing 5 to clear_refs resets the peak RSS (Linux >= 4.0).
    with open(f"/proc/{pid}/clear_refs", "w") as f:
        f.write("5")


def main():
    png = plan_png()
    data = tempfile.mkdtemp()
    proc = subprocess.Popen([f"{BIN}/planner-service", "serve", "--listen", "127.0.0.1:0",
                             "--data-dir", data, "--token", TOKEN, "--zenoh-listen", "tcp/127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    url = None
    for line in proc.stdout:
        m = re.match(r"listening on (\S+)", line)
        if m:
            url = m.group(1)
            break
    db = os.path.join(data, "maps", "maps.redb")
    res = {"png_bytes": len(png), "pixels": 20000 * 5000}
    try:
        size0 = os.path.getsize(db)
        body, ctype = multipart({"name": "big", "resolution_m": "0.05"}, {"picture": ("big.png", png)})
        reset_hwm(proc.pid)
        base = hwm_mb(proc.pid)
        t = time.monotonic()
        req = urllib.request.Request(f"{url}/api/v1/maps", data=body, method="POST",
                                     headers={"Content-Type": ctype, "Authorization": f"Bearer {TOKEN}"})
        with urllib.request.urlopen(req, timeout=300) as r:
            res["upload_status"] = r.status
        res["upload_s"] = round(time.monotonic() - t, 2)
        res["upload_peak_rss_mb"] = round(hwm_mb(proc.pid))
        res["rss_before_mb"] = round(base)
        res["store_growth_mb"] = round((os.path.getsize(db) - size0) / 2**20, 2)
        res["store_file_mb"] = round(os.path.getsize(db) / 2**20, 2)
        for k in ("image_first_s", "image_second_s"):
            t = time.monotonic()
            with urllib.request.urlopen(f"{url}/api/v1/maps/big/image", timeout=300) as r:
                r.read()
            res[k] = round(time.monotonic() - t, 3)
        body, ctype = multipart({"resolution_m": "0.05"}, {"picture": ("big.png", png)})
        reset_hwm(proc.pid)
        codes = []

        def preview():
            req = urllib.request.Request(f"{url}/api/v1/maps/preview", data=body, method="POST",
                                         headers={"Content-Type": ctype, "Authorization": f"Bearer {TOKEN}"})
            try:
                with urllib.request.urlopen(req, timeout=300) as r:
                    r.read()
                    codes.append(r.status)
            except urllib.error.HTTPError as e:
                codes.append(e.code)

        t = time.monotonic()
        threads = [threading.Thread(target=preview) for _ in range(3)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        res["three_previews_s"] = round(time.monotonic() - t, 2)
        res["three_previews_status"] = sorted(codes)
        res["three_previews_peak_rss_mb"] = round(hwm_mb(proc.pid))
    finally:
        proc.terminate()
        proc.wait()
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
